"""OPC UA server settings: the `servers.opcua` section of tagdb.yaml plus command-line overrides.

Defaults depend on where the server listens. On a loopback address (development) it offers
SecurityPolicy None as well as Basic256Sha256 Sign and SignAndEncrypt, and lets anonymous
clients read. On any other address it offers only Basic256Sha256 and refuses anonymous
clients, unless the YAML says otherwise (None on a non-loopback address is logged as a warning).
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import urlparse

from softplc.core.roles import Role
from softplc.protocols.opcua_names import DEFAULT_NAMESPACE

if TYPE_CHECKING:
    from asyncua import ua

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/softplc/"
DEFAULT_APPLICATION_URI = "urn:softplc:server"
DEFAULT_FOLDER_SIZE = 100
# Transport limits (asyncua's defaults are 100 MB messages of up to 1601 chunks, which an
# unauthenticated peer may send). 4 MB holds the biggest Read/Write we serve many times over;
# 512 chunks let a client with the smallest buffer the spec allows (8 KB) send a full message.
DEFAULT_MAX_MESSAGE_SIZE = 4 * 1024 * 1024
DEFAULT_MAX_CHUNK_COUNT = 512
DEFAULT_MAX_CONNECTIONS_PER_PEER = 50

POLICY_NONE = "None"
POLICY_SIGN = "Basic256Sha256_Sign"
POLICY_ENCRYPT = "Basic256Sha256_SignAndEncrypt"
_POLICY_TYPES = {POLICY_NONE: "NoSecurity", POLICY_SIGN: "Basic256Sha256_Sign", POLICY_ENCRYPT: "Basic256Sha256_SignAndEncrypt"}


class _PolicyTypes(Mapping[str, "ua.SecurityPolicyType"]):
    """Policy name → asyncua's SecurityPolicyType, imported on first lookup: every configuration
    load checks these settings (softplc.adapters.opcua.section), and must not pay for asyncua."""

    def __contains__(self, name: object) -> bool:
        return name in _POLICY_TYPES

    def __getitem__(self, name: str) -> ua.SecurityPolicyType:
        from asyncua import ua

        return getattr(ua.SecurityPolicyType, _POLICY_TYPES[name])

    def __iter__(self) -> Iterator[str]:
        return iter(_POLICY_TYPES)

    def __len__(self) -> int:
        return len(_POLICY_TYPES)


POLICIES: Mapping[str, ua.SecurityPolicyType] = _PolicyTypes()
POLICY_TEXT = {POLICY_NONE: "None", POLICY_SIGN: "Basic256Sha256 Sign", POLICY_ENCRYPT: "Basic256Sha256 SignAndEncrypt"}


class SettingsError(ValueError):
    """A bad OPC UA setting; `key` is the key under servers.opcua it belongs to."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True)
class OpcUaSettings:
    """Everything the OPC UA adapter needs to start; paths left None default into the state dir."""

    endpoint: str = DEFAULT_ENDPOINT
    namespace: str = DEFAULT_NAMESPACE
    application_uri: str = DEFAULT_APPLICATION_URI
    security: tuple[str, ...] | None = None  # None: default for the bind address
    anonymous: str | None = None  # "off" | "viewer"; None: default for the bind address
    users_file: Path | None = None  # default <state_dir>/users.yaml
    pki_dir: Path | None = None  # default <state_dir>/pki
    certificate: Path | None = None  # an existing server certificate (with private_key)
    private_key: Path | None = None
    folder_size: int = DEFAULT_FOLDER_SIZE
    max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE  # bytes of one request, all chunks
    max_chunk_count: int = DEFAULT_MAX_CHUNK_COUNT
    max_connections_per_peer: int = DEFAULT_MAX_CONNECTIONS_PER_PEER  # per client IP address
    enabled: bool = True

    def __post_init__(self) -> None:
        self.parsed_endpoint()  # raise early on a malformed endpoint
        for policy in self.security or ():
            if policy not in POLICIES:
                raise SettingsError("security", f"unknown security policy '{policy}'; expected one of: {', '.join(POLICIES)}")
        if self.security is not None and not self.security:
            raise SettingsError("security", "offer at least one security policy")
        if self.anonymous not in (None, "off", "viewer"):
            raise SettingsError("anonymous", f"anonymous must be off or viewer, not '{self.anonymous}'")
        if self.certificate is not None and self.private_key is None or self.private_key is not None and self.certificate is None:
            raise SettingsError("certificate", "give both certificate and private_key, or neither")
        if not 10 <= self.folder_size <= 10_000:
            raise SettingsError("folder_size", "folder_size must be between 10 and 10000")
        if not 65_536 <= self.max_message_size <= 256 * 1024 * 1024:
            raise SettingsError("max_message_size", "max_message_size must be between 65536 and 268435456 bytes")
        if not 1 <= self.max_chunk_count <= 8192:
            raise SettingsError("max_chunk_count", "max_chunk_count must be between 1 and 8192")
        if not 1 <= self.max_connections_per_peer <= 1000:
            raise SettingsError("max_connections_per_peer", "max_connections_per_peer must be between 1 and 1000")

    @classmethod
    def from_section(cls, section: dict[str, Any] | None, base_dir: Path) -> OpcUaSettings:
        """Settings from the (schema-checked) `servers.opcua` mapping; paths relative to base_dir."""
        section = dict(section or {})

        def path(key: str) -> Path | None:
            value = section.get(key)
            return None if value is None else (base_dir / str(value))

        security = section.get("security")
        return cls(
            endpoint=str(section.get("endpoint", DEFAULT_ENDPOINT)),
            namespace=str(section.get("namespace", DEFAULT_NAMESPACE)),
            application_uri=str(section.get("application_uri", DEFAULT_APPLICATION_URI)),
            security=tuple(security) if security is not None else None,
            anonymous=section.get("anonymous"),
            users_file=path("users_file"),
            pki_dir=path("pki_dir"),
            certificate=path("certificate"),
            private_key=path("private_key"),
            folder_size=int(section.get("folder_size", DEFAULT_FOLDER_SIZE)),
            max_message_size=int(section.get("max_message_size", DEFAULT_MAX_MESSAGE_SIZE)),
            max_chunk_count=int(section.get("max_chunk_count", DEFAULT_MAX_CHUNK_COUNT)),
            max_connections_per_peer=int(section.get("max_connections_per_peer", DEFAULT_MAX_CONNECTIONS_PER_PEER)),
            enabled=bool(section.get("enabled", True)),
        )

    def with_overrides(self, **changes: Any) -> OpcUaSettings:
        """A copy with the given fields replaced (None values are ignored)."""
        return replace(self, **{key: value for key, value in changes.items() if value is not None})

    def with_port(self, port: int) -> OpcUaSettings:
        """A copy whose endpoint has this port (0: any free port), host and path unchanged."""
        host, _, path = self.parsed_endpoint()
        netloc = f"[{host}]" if ":" in host else host
        return replace(self, endpoint=f"opc.tcp://{netloc}:{port}{path}")

    # -- derived ------------------------------------------------------------------------

    def parsed_endpoint(self) -> tuple[str, int, str]:
        """(host, port, path) of the endpoint URL."""
        url = urlparse(self.endpoint)
        if url.scheme != "opc.tcp" or not url.hostname:
            raise SettingsError("endpoint", f"endpoint must look like opc.tcp://HOST:PORT/PATH, not '{self.endpoint}'")
        try:
            port = url.port if url.port is not None else 4840
        except ValueError:
            raise SettingsError("endpoint", f"bad port in endpoint '{self.endpoint}'") from None
        return url.hostname, port, url.path or "/"

    @property
    def host(self) -> str:
        return self.parsed_endpoint()[0]

    @property
    def port(self) -> int:
        return self.parsed_endpoint()[1]

    @property
    def loopback(self) -> bool:
        host = self.host
        if host == "localhost":
            return True
        try:
            return ipaddress.ip_address(host).is_loopback
        except ValueError:
            return False

    @property
    def policies(self) -> tuple[str, ...]:
        if self.security is not None:
            return tuple(dict.fromkeys(self.security))
        if self.loopback:
            return (POLICY_NONE, POLICY_SIGN, POLICY_ENCRYPT)
        return (POLICY_SIGN, POLICY_ENCRYPT)

    @property
    def secured(self) -> bool:
        return any(policy != POLICY_NONE for policy in self.policies)

    @property
    def anonymous_role(self) -> Role | None:
        mode = self.anonymous if self.anonymous is not None else ("viewer" if self.loopback else "off")
        return Role.VIEWER if mode == "viewer" else None

    def users_path(self, state_dir: Path) -> Path:
        return self.users_file if self.users_file is not None else state_dir / "users.yaml"

    def pki_path(self, state_dir: Path) -> Path:
        return self.pki_dir if self.pki_dir is not None else state_dir / "pki"

