"""Connecting to a softplc OPC UA server from Python: for robot agents, tools and tests.

    certificate = ensure_client_certificate(Path("agent-pki"), "robot7")   # made once, then reused
    client = await make_client("opc.tcp://plc:4840/softplc/", certificate=certificate,
                               security="Basic256Sha256_SignAndEncrypt", login_with_certificate=True)
    async with client:
        ns = await client.get_namespace_index(DEFAULT_NAMESPACE)
        ...

The first connection with a new certificate is refused (BadCertificateUntrusted) until an
administrator runs `softplc opcua trust <fingerprint>` on the server; `fingerprint(certificate)`
gives what to tell them. A user entry with `--certificate` logs the agent in without a password.
"""

from __future__ import annotations

import datetime
import fcntl
from dataclasses import dataclass
from pathlib import Path

from asyncua import Client, ua
from asyncua.crypto.cert_gen import dump_private_key_as_pem, generate_private_key, generate_self_signed_app_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

from softplc.security.certificates import der_bytes, load_certificate_file
from softplc.security.certificates import fingerprint as der_fingerprint

_MODES = {
    "Basic256Sha256_Sign": ua.MessageSecurityMode.Sign,
    "Basic256Sha256_SignAndEncrypt": ua.MessageSecurityMode.SignAndEncrypt,
}


@dataclass(frozen=True)
class ClientCertificate:
    """A client application certificate (DER), its private key (PEM) and its ApplicationUri."""

    certificate: Path
    private_key: Path
    application_uri: str

    @property
    def der(self) -> bytes:
        return self.certificate.read_bytes()

    @property
    def fingerprint(self) -> str:
        return der_fingerprint(self.der)


def ensure_client_certificate(directory: Path, name: str, application_uri: str | None = None, days: int = 5 * 365) -> ClientCertificate:
    """The certificate NAME.der / NAME.key.pem in `directory`, made (self-signed) if missing or expired."""
    directory.mkdir(parents=True, exist_ok=True)
    # Two clients started at once on first use (two terminals, parallel tests) must not each write
    # half of a pair: one makes it, the other waits and uses it.
    with open(directory / f".{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _existing_or_new(directory, name, application_uri or f"urn:softplc:client:{name}", days)


def _existing_or_new(directory: Path, name: str, uri: str, days: int) -> ClientCertificate:
    certificate_path, key_path = directory / f"{name}.der", directory / f"{name}.key.pem"
    if certificate_path.exists() and key_path.exists():
        existing = load_certificate_file(certificate_path)
        if existing.not_valid_after_utc > datetime.datetime.now(datetime.timezone.utc):
            uris = existing.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
            found = uris.get_values_for_type(x509.UniformResourceIdentifier)
            return ClientCertificate(certificate_path, key_path, found[0] if found else uri)
    key = generate_private_key()
    certificate = generate_self_signed_app_certificate(
        key, name, {}, [x509.UniformResourceIdentifier(uri), x509.DNSName("localhost")],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH], days=days,
    )
    key_path.write_bytes(dump_private_key_as_pem(key))
    key_path.chmod(0o600)
    certificate_path.write_bytes(der_bytes(certificate))
    return ClientCertificate(certificate_path, key_path, uri)


def client_certificate(certificate: Path, private_key: Path) -> ClientCertificate:
    """A certificate and key given by a user, with the ApplicationUri its certificate names (ValueError if unreadable)."""
    loaded = load_certificate_file(certificate)
    try:
        names = loaded.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        uris = names.get_values_for_type(x509.UniformResourceIdentifier)
    except x509.ExtensionNotFound:
        uris = []
    return ClientCertificate(certificate, private_key, uris[0] if uris else f"urn:softplc:client:{certificate.stem}")


def pem_certificate(certificate: ClientCertificate) -> bytes:
    """The certificate as PEM (some clients, e.g. node-opcua, want PEM files)."""
    return load_certificate_file(certificate.certificate).public_bytes(serialization.Encoding.PEM)


async def make_client(
    endpoint: str,
    *,
    user: str | None = None,
    password: str | None = None,
    certificate: ClientCertificate | None = None,
    security: str = "None",
    login_with_certificate: bool = False,
    timeout: float = 4.0,
    watchdog_interval: float = 1.0,
) -> Client:
    """An asyncua Client for a softplc server (not yet connected: use `async with client:`).

    `security` is a softplc policy name: None, Basic256Sha256_Sign or
    Basic256Sha256_SignAndEncrypt (which need `certificate`). With `login_with_certificate`
    the session logs in with the certificate (an X509 identity token) instead of a user name;
    with neither, it is anonymous. Every `watchdog_interval` seconds the client reads the
    server's state to notice a server that stopped answering (`client.connection_lost_callback`).
    """
    client = Client(endpoint, timeout=timeout, watchdog_intervall=watchdog_interval)
    if user is not None:
        client.set_user(user)
        client.set_password(password or "")
    if security != "None":
        if certificate is None:
            raise ValueError(f"security {security} needs a client certificate")
        if security not in _MODES:
            raise ValueError(f"unknown security '{security}'; expected None or one of {', '.join(_MODES)}")
        client.application_uri = certificate.application_uri
        await client.set_security(
            SecurityPolicyBasic256Sha256, str(certificate.certificate), str(certificate.private_key), mode=_MODES[security]
        )
        if login_with_certificate:
            await client.load_client_certificate(str(certificate.certificate))
            await client.load_private_key(str(certificate.private_key))
    return client
