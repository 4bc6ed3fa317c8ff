"""OPC UA client security for the latency client: `--security MODE[,CERT,KEY]`.

MODE is None, Sign or SignAndEncrypt (policy Basic256Sha256). Without CERT and KEY a
self-signed client application certificate is made; the server must trust it (our own runtime
does so itself; another server needs it copied to its trust list).
"""

from __future__ import annotations

from pathlib import Path

from asyncua import ua
from asyncua.crypto.cert_gen import dump_private_key_as_pem, generate_private_key, generate_self_signed_app_certificate
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

# --security MODE[,CERT,KEY] is every client command's (softplc/clients/login.py): the same here.
from softplc.clients.login import Security
from softplc.clients.login import application_uri as _application_uri

MODES = {"None": ua.MessageSecurityMode.None_, "Sign": ua.MessageSecurityMode.Sign,
         "SignAndEncrypt": ua.MessageSecurityMode.SignAndEncrypt}
APPLICATION_URI = "urn:softplc:latency-client"
__all__ = ["APPLICATION_URI", "MODES", "Security", "application_uri", "make_client_certificate"]


def make_client_certificate(directory: Path) -> tuple[Path, Path]:
    """A self-signed OPC UA client certificate (DER) and key (PEM) in `directory`."""
    directory.mkdir(parents=True, exist_ok=True)
    key = generate_private_key()
    certificate = generate_self_signed_app_certificate(
        key, "softplc latency client", {"organizationName": "softplc"},
        [x509.UniformResourceIdentifier(APPLICATION_URI), x509.DNSName("localhost")],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH], days=365,
    )
    certificate_path, key_path = directory / "latency-client.der", directory / "latency-client.pem"
    certificate_path.write_bytes(certificate.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(dump_private_key_as_pem(key))
    key_path.chmod(0o600)
    return certificate_path, key_path


def application_uri(certificate: Path) -> str:
    """The application URI in a certificate's subjectAltName (asyncua must announce the same)."""
    return _application_uri(certificate, APPLICATION_URI)
