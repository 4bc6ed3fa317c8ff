"""How a softplc command logs in to an OPC UA server: one option set and one helper for every client command.

    softplc read t01_iBL --endpoint opc.tcp://plc7:4840/softplc/ --user alice --security SignAndEncrypt
    echo "$PASSWORD" | softplc write t01_iFr=45 --user alice --password-stdin
    SOFTPLC_PASSWORD=... softplc watch 't01_*' --user alice
    softplc alarms list --config /srv/line2/tagdb.yaml    # where that plant serves, and its namespace

- `--endpoint URL`, else the `servers.opcua` endpoint of the plant's configuration (`--config
  FILE`, default `tagdb.yaml` if there is one here), else a softplc on this machine
  (`opc.tcp://127.0.0.1:4840/softplc/`); the tags' namespace likewise (`--namespace URI`, else the
  configuration's, else `urn:softplc:tags`). A redundant pair: `--endpoint URL1,URL2` (or a
  configuration whose `redundancy:` section names the members' `opcua:` endpoints) — the command
  connects to the one whose ServiceLevel says it is active (≥ 200; docs/redundancy.md);
- `--user NAME`, the password from `--password-stdin` (the first line of stdin), else the
  environment (`$SOFTPLC_PASSWORD`; `softplc latency`: `$SOFTPLC_LATENCY_PASSWORD`), else a
  prompt when stdin is a terminal — never on the command line, where `ps` shows it; without
  `--user` the session is anonymous (on a softplc: read only);
- `--security MODE[,CERT,KEY]`: None, Sign or SignAndEncrypt (Basic256Sha256) with the client
  certificate (DER or PEM) and its key; without CERT,KEY a certificate is made once in
  `~/.softplc/client/` and kept — the server must trust it (`softplc opcua trust FINGERPRINT`).

`connect()` turns every way a connection or login fails into a `LoginError` whose message says
what to do, and whose `exit_status` is the one every client command gives for it (3 cannot
connect, 4 refused, 2 contradicting options; docs/operations.md, "Exit statuses").
"""

from __future__ import annotations

import argparse
import asyncio
import getpass
import logging
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from softplc.clients.endpoints import DEFAULT_CONFIG, DEFAULT_ENDPOINT, endpoint_urls, pair_endpoints, reachable
from softplc.protocols.opcua_names import DEFAULT_NAMESPACE

if TYPE_CHECKING:  # asyncua is imported by connect() only: `softplc --help` must not load it
    from asyncua import Client

log = logging.getLogger(__name__)

PASSWORD_ENV = "SOFTPLC_PASSWORD"
MODE_NAMES = ("None", "Sign", "SignAndEncrypt")
DEFAULT_CERTIFICATE_DIR = Path.home() / ".softplc" / "client"
CLIENT_NAME = "softplc-client"


class LoginError(Exception):
    """No session: `kind` is "connect" (no server there, a timeout), "refused" (login, certificate, policy)
    or "usage" (options that contradict each other)."""

    def __init__(self, message: str, kind: str = "connect") -> None:
        super().__init__(message)
        self.kind = kind

    @property
    def exit_status(self) -> int:
        """The exit status of every OPC UA client command for this failure: 3 no connection, 4 refused, 2 usage."""
        return {"connect": 3, "refused": 4, "usage": 2}[self.kind]


@dataclass(frozen=True)
class Security:
    """A parsed --security: the mode and, for Sign/SignAndEncrypt, the client certificate and key."""

    mode: str
    certificate: Path | None = None
    key: Path | None = None

    @property
    def secured(self) -> bool:
        return self.mode != "None"

    def text(self) -> str:
        if not self.secured:
            return "None"
        return f"{self.mode},{self.certificate},{self.key}"

    @classmethod
    def parse(cls, text: str) -> Security:
        """Parse MODE[,CERT,KEY] (MODE also as Basic256Sha256_MODE); raises ValueError with the reason."""
        parts = [part.strip() for part in text.split(",")]
        mode = {name.lower(): name for name in MODE_NAMES}.get(parts[0].lower().removeprefix("basic256sha256_"))
        if mode is None or len(parts) not in (1, 3):
            raise ValueError(f"bad --security {text!r}; write None, Sign or SignAndEncrypt, optionally followed by ,CERT,KEY")
        if len(parts) == 3:
            certificate, key = Path(parts[1]), Path(parts[2])
            for path in (certificate, key):
                if not path.is_file():
                    raise ValueError(f"--security: no such file {path}")
            return cls(mode, certificate, key)
        return cls(mode)


def application_uri(certificate: Path, default: str = "urn:softplc:client") -> str:
    """The application URI in a certificate's subjectAltName (the client must announce the same)."""
    from cryptography import x509

    data = certificate.read_bytes()
    loaded = x509.load_pem_x509_certificate(data) if data.startswith(b"-----") else x509.load_der_x509_certificate(data)
    try:
        names = loaded.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return default
    uris = names.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else default


@dataclass(frozen=True)
class Login:
    """Where and as whom to connect."""

    endpoint: str = DEFAULT_ENDPOINT
    user: str | None = None
    password: str | None = None
    security: Security = Security("None")
    timeout: float = 4.0
    namespace: str = DEFAULT_NAMESPACE

    @property
    def endpoints(self) -> list[str]:
        """The endpoints given (several for a redundant pair: comma separated)."""
        return [part.strip() for part in self.endpoint.split(",") if part.strip()] or [DEFAULT_ENDPOINT]


def _security_argument(text: str) -> Security:
    try:
        return Security.parse(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_login_arguments(
    parser: argparse.ArgumentParser,
    *,
    endpoint: bool = True,
    timeout: bool = True,
    timeout_default: float = 4.0,
    password_env: str = PASSWORD_ENV,
    user_help: str = "",
    security_help: str | None = None,
) -> None:
    """Add --endpoint, --config, --namespace and --timeout (unless the command has its own), --user, --password-stdin, --security."""
    group = parser.add_argument_group("connection and login (OPC UA)")
    if endpoint:
        group.add_argument("--endpoint", metavar="URL", type=endpoint_urls,
                           help=f"the runtime's OPC UA endpoint (default: servers.opcua.endpoint of --config, else {DEFAULT_ENDPOINT}); "
                           "a redundant pair's two endpoints comma separated: the active one is used")
        group.add_argument("--config", metavar="FILE",
                           help=f"the plant's configuration, for its endpoint and namespace (default {DEFAULT_CONFIG} if there is one here)")
        group.add_argument("--namespace", metavar="URI",
                           help=f"the namespace URI of the runtime's tags (default: servers.opcua.namespace of --config, else {DEFAULT_NAMESPACE})")
    group.add_argument("--user", metavar="NAME",
                       help=f"log in as NAME; the password from --password-stdin, ${password_env} or a prompt "
                       f"(default: anonymous, which a softplc lets only read){user_help}")
    group.add_argument("--password-stdin", action="store_true", help="read the password from the first line of stdin")
    group.add_argument("--security", type=_security_argument, metavar="MODE[,CERT,KEY]",
                       help=security_help or "None (default), Sign or SignAndEncrypt (Basic256Sha256), optionally with "
                       "the client certificate and key; without them one is made in ~/.softplc/client/ "
                       "(the server must trust it: softplc opcua trust FINGERPRINT)")
    if timeout:
        group.add_argument("--timeout", type=_seconds, default=timeout_default, metavar="S",
                           help=f"seconds to wait for each answer (default {timeout_default:g})")
    parser.set_defaults(password_env=password_env, login_config=endpoint)  # login_config: --config is ours (not, e.g., audit's)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not 0 < value < 3600:
        raise argparse.ArgumentTypeError(f"{text} is out of range: more than 0 and less than 3600 seconds")
    return value


def read_password(args: argparse.Namespace, stdin: TextIO | None = None) -> str | None:
    """The password for --user: from stdin (--password-stdin), the environment, or a prompt; None without --user."""
    if not getattr(args, "user", None):
        if getattr(args, "password_stdin", False):
            raise LoginError("--password-stdin needs --user NAME", "usage")
        return None
    stdin = stdin or sys.stdin
    env_name = getattr(args, "password_env", PASSWORD_ENV)
    if getattr(args, "password_stdin", False):
        return stdin.readline().rstrip("\r\n")
    if os.environ.get(env_name) is not None:
        return os.environ[env_name]
    if stdin.isatty():
        return getpass.getpass(f"password for {args.user}: ")
    raise LoginError(f"no password for --user {args.user}: give --password-stdin or ${env_name} (no terminal to ask on)", "refused")


def login_from_args(args: argparse.Namespace, stdin: TextIO | None = None) -> Login:
    """The Login the options describe (the password read now); raises LoginError."""
    endpoint, namespace = where(args)
    return Login(
        endpoint=endpoint, user=args.user or None, password=read_password(args, stdin),
        security=args.security or Security("None"), timeout=args.timeout, namespace=namespace,
    )


def where(args: argparse.Namespace) -> tuple[str, str]:
    """The endpoint and namespace: --endpoint/--namespace, else those of --config's servers.opcua, else the defaults."""
    endpoint = (getattr(args, "endpoint", None) or "").strip() or None
    namespace = getattr(args, "namespace", None) or None
    if (endpoint is not None and namespace is not None) or not getattr(args, "login_config", False):
        return endpoint or DEFAULT_ENDPOINT, namespace or DEFAULT_NAMESPACE
    section = _opcua_section(args.config)
    if endpoint is None:
        endpoint = pair_endpoints(args.config) or reachable(section.get("endpoint")) or DEFAULT_ENDPOINT
    if namespace is None:
        namespace = section.get("namespace") if isinstance(section.get("namespace"), str) else DEFAULT_NAMESPACE
    return endpoint, namespace


def _opcua_section(config: str | None) -> dict[str, object]:
    """servers.opcua of the configuration (only that: the rest of the file is not checked); {} without a file."""
    from softplc.config.yamlsource import ConfigError, load_yaml

    path = Path(config or DEFAULT_CONFIG)
    if not path.is_file():
        if config is None:  # no plant here: the defaults
            return {}
        raise LoginError(f"--config {config}: no such file (give the plant's configuration, or --endpoint URL)", "usage")
    try:
        data, _ = load_yaml(path)
    except (ConfigError, OSError) as error:
        if config is None:  # only found here, not asked for: a file being edited must not stop `--endpoint URL`
            log.warning("ignoring %s for the endpoint and namespace: %s", path, error)
            return {}
        raise LoginError(f"cannot read {path} for the endpoint: {error} (or give --endpoint URL)", "usage") from None
    servers = data.get("servers") if isinstance(data, dict) else None
    section = servers.get("opcua") if isinstance(servers, dict) else None
    return section if isinstance(section, dict) else {}


def with_certificate(security: Security, directory: Path = DEFAULT_CERTIFICATE_DIR) -> Security:
    """A secured mode without CERT,KEY gets the client certificate kept in `directory` (made once)."""
    if not security.secured or security.certificate is not None:
        return security
    from softplc.protocols.opcua_client import ensure_client_certificate

    made = ensure_client_certificate(directory, CLIENT_NAME)
    return Security(security.mode, made.certificate, made.private_key)


SERVICE_LEVEL_HEALTHY = 200  # OPC UA Part 4 §6.6.2.4.2: 200-255 is a healthy server (a pair's active)


async def connect(login: Login, certificate_dir: Path = DEFAULT_CERTIFICATE_DIR) -> Client:
    """A connected asyncua Client (close it with `await client.disconnect()`); raises LoginError.

    With several endpoints (a redundant pair), the first whose ServiceLevel is healthy (the
    active), else the one with the highest ServiceLevel (a standby: reads work, writes are refused).
    """
    endpoints = login.endpoints
    if len(endpoints) == 1:
        return await _connect_one(login, endpoints[0], certificate_dir)
    best: tuple[int, Client] | None = None
    failures: list[LoginError] = []
    for endpoint in endpoints:
        try:
            client = await _connect_one(login, endpoint, certificate_dir)
        except LoginError as error:
            failures.append(error)
            continue
        level = await service_level(client)
        if level >= SERVICE_LEVEL_HEALTHY:
            if best is not None:
                await _close(best[1])
            return client
        if best is None or level > best[0]:
            if best is not None:
                await _close(best[1])
            best = (level, client)
        else:
            await _close(client)
    if best is not None:
        return best[1]
    refused = [failure for failure in failures if failure.kind == "refused"]
    raise LoginError("; ".join(str(failure) for failure in failures), "refused" if refused else "connect")


async def service_level(client: Client) -> int:
    """The server's ServiceLevel (255 for a server alone; 0 when it cannot be read)."""
    from asyncua import ua

    try:
        value = await client.get_node(ua.NodeId(ua.ObjectIds.Server_ServiceLevel)).read_value()
    except Exception:  # an old or odd server: count it as the least healthy
        return 0
    return int(value) if isinstance(value, int) else 0


async def _connect_one(login: Login, endpoint: str, certificate_dir: Path) -> Client:
    from asyncua import ua

    from softplc.protocols.opcua_client import ClientCertificate, make_client

    security = with_certificate(login.security, certificate_dir)
    certificate = None
    if security.certificate is not None and security.key is not None:
        certificate = ClientCertificate(security.certificate, security.key, application_uri(security.certificate))
    try:
        client = await make_client(
            endpoint, user=login.user, password=login.password, certificate=certificate,
            security="None" if not security.secured else f"Basic256Sha256_{security.mode}", timeout=login.timeout,
        )
    except (ValueError, OSError) as error:
        raise LoginError(f"--security: {error}", "refused") from None
    try:
        await client.connect()
    except ua.UaStatusCodeError as error:
        await _close(client)
        raise LoginError(_refusal(login, error.code, certificate, endpoint), "refused" if _is_refusal(error.code) else "connect") from None
    except (OSError, asyncio.TimeoutError, ConnectionError) as error:
        await _close(client)
        raise LoginError(f"cannot connect to {endpoint}: {_describe(error)} (is `softplc run` serving OPC UA there?)") from None
    except Exception as error:  # asyncua raises plain Exceptions for some protocol mismatches
        await _close(client)
        raise LoginError(f"cannot connect to {endpoint}: {_describe(error)}") from None
    return client


async def _close(client: Client) -> None:
    try:
        await client.disconnect()
    except Exception:  # half-open: nothing left to close cleanly
        client.disconnect_socket()


# What a server answers when it will not have this client (wrong password, an identity or a
# certificate it does not accept): not worth retrying. The robot agent refuses on the same list.
REFUSALS = {
    "BadUserAccessDenied": "login refused: wrong user name or password, or too many failed logins from here (wait a minute)",
    "BadIdentityTokenInvalid": "login refused: this server does not accept that kind of login",
    "BadIdentityTokenRejected": "login refused: wrong user name or password",
    "BadCertificateUntrusted": "the server does not trust this client's certificate",
    "BadSecurityChecksFailed": "the server refused this client's certificate or security settings",
    "BadCertificateInvalid": "the server refused this client's certificate as invalid",
    "BadCertificateTimeInvalid": "this client's certificate has expired or is not valid yet",
    "BadCertificateUriInvalid": "the server refused this client's certificate: its application URI is not the one the client gives",
    "BadSecurityPolicyRejected": "the server does not offer this security mode here",
}


def _is_refusal(code: int) -> bool:
    from asyncua import ua

    return ua.StatusCode(code).name in REFUSALS


def _refusal(login: Login, code: int, certificate: object, endpoint: str | None = None) -> str:
    from asyncua import ua

    endpoint = endpoint or login.endpoint
    name = ua.StatusCode(code).name
    text = REFUSALS.get(name)
    if text is None:
        return f"cannot open a session on {endpoint}: {name}"
    text = f"{endpoint}: {text} ({name})"
    if login.user is None and name in ("BadUserAccessDenied", "BadIdentityTokenRejected", "BadIdentityTokenInvalid"):
        text = f"{endpoint}: anonymous sessions are refused here: log in with --user NAME ({name})"
    if name in ("BadCertificateUntrusted", "BadSecurityChecksFailed") and certificate is not None:
        text += f"; on the server run: softplc opcua trust {getattr(certificate, 'fingerprint', '?')[:16]}"
    if name == "BadSecurityPolicyRejected" and not login.security.secured:
        text += "; try --security SignAndEncrypt"
    return text


def _describe(error: BaseException) -> str:
    if isinstance(error, asyncio.TimeoutError):
        return "no answer (timed out)"
    if isinstance(error, ConnectionRefusedError):
        return "connection refused"
    return str(error) or type(error).__name__
