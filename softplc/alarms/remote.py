"""Calling a running runtime's commands over OPC UA (`Objects/Commands.Call`), for `softplc alarms`.

    async with RemoteCommands(endpoint, user="otto", password=..., security="None") as remote:
        alarms = await remote.call("alarms.list", {"state": "unacknowledged"})

A refusal raises `RemoteRefused`: `by_role` when the session's role may not (BadUserAccessDenied),
otherwise with the runtime's own reason. Connection and login problems raise `RemoteError`.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import TracebackType
from typing import Any

DEFAULT_NAMESPACE = "urn:softplc:tags"


class RemoteError(Exception):
    """The runtime could not be reached or refused the login; the message says what to do."""


class RemoteRefused(Exception):
    """A command the runtime did not carry out."""

    def __init__(self, message: str, *, by_role: bool = False) -> None:
        super().__init__(message)
        self.by_role = by_role


class RemoteCommands:
    """One OPC UA session to a runtime, calling its commands."""

    def __init__(self, endpoint: str, *, user: str | None = None, password: str | None = None, security: str = "None",
                 certificate: Path | None = None, private_key: Path | None = None, namespace: str = DEFAULT_NAMESPACE,
                 timeout: float = 10.0) -> None:
        self.endpoint = endpoint
        self.user = user
        self.password = password
        self.security = security
        self.certificate = certificate
        self.private_key = private_key
        self.namespace = namespace
        self.timeout = timeout
        self._client: Any = None
        self._node: Any = None
        self._method: Any = None

    async def __aenter__(self) -> RemoteCommands:
        from asyncua import ua
        from asyncua.ua.uaerrors import BadUserAccessDenied, UaError

        from softplc.opcua.client import ClientCertificate, ensure_client_certificate, make_client

        certificate = None
        if self.security != "None":
            if self.certificate is not None and self.private_key is not None:
                certificate = ClientCertificate(self.certificate, self.private_key, "urn:softplc:client:softplc-cli")
            else:
                certificate = ensure_client_certificate(Path.home() / ".softplc" / "cli-client", "softplc-cli")
        try:
            client = await make_client(self.endpoint, user=self.user, password=self.password, certificate=certificate,
                                       security=self.security, timeout=self.timeout)
        except ValueError as error:
            raise RemoteError(str(error)) from None
        client.session_timeout = 60_000  # what a softplc server grants; asyncua would warn about its 1 h ask
        try:
            await client.connect()
        except BadUserAccessDenied:
            who = f"user {self.user!r}" if self.user else "an anonymous session"
            raise RemoteError(f"{self.endpoint} refused the login of {who}: check the user name and $SOFTPLC_PASSWORD") from None
        except (OSError, TimeoutError, UaError) as error:
            hint = ""
            if "BadCertificateUntrusted" in type(error).__name__ + str(error) and certificate is not None:
                hint = f"; on the server, trust this client: softplc opcua trust {certificate.fingerprint[:16]}"
            raise RemoteError(f"cannot connect to {self.endpoint}: {_describe(error)}{hint}") from None
        self._client = client
        try:
            index = await client.get_namespace_index(self.namespace)
        except (ValueError, UaError):
            await self._close()
            raise RemoteError(f"{self.endpoint} has no namespace {self.namespace!r}: is it a softplc runtime? (--namespace)") from None
        self._node = client.get_node(ua.NodeId("Commands", index))
        self._method = ua.NodeId("Commands.Call", index)
        return self

    async def __aexit__(self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None) -> None:
        await self._close()

    async def _close(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            try:
                await client.disconnect()
            except Exception:  # noqa: BLE001 — the session is gone either way
                pass

    async def call(self, name: str, arguments: dict[str, Any] | None = None) -> Any:
        """The command's result; raises RemoteRefused or RemoteError."""
        from asyncua.ua.uaerrors import BadNodeIdUnknown, BadUserAccessDenied, UaError

        try:
            text = await self._node.call_method(self._method, name, json.dumps(arguments or {}))
        except BadUserAccessDenied:
            raise RemoteRefused(f"{name}: refused for the role of this session", by_role=True) from None
        except BadNodeIdUnknown:
            raise RemoteError(f"{self.endpoint} has no Commands object: a softplc runtime older than its alarms?") from None
        except (OSError, TimeoutError, UaError) as error:
            raise RemoteError(f"{name} over {self.endpoint} failed: {_describe(error)}") from None
        reply = json.loads(text)
        if not reply.get("ok"):
            raise RemoteRefused(reply.get("error", "refused"))
        return reply.get("result")


def _describe(error: BaseException) -> str:
    text = str(error).strip()
    return f"{type(error).__name__}: {text}" if text else type(error).__name__
