"""OPC UA client security for the latency client: `--security MODE[,CERT,KEY]`.

MODE is None, Sign or SignAndEncrypt (policy Basic256Sha256). Without CERT and KEY a
self-signed client application certificate is made; the server must trust it (our own runtime
does so itself; another server needs it copied to its trust list).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from asyncua import ua
from asyncua.crypto.cert_gen import dump_private_key_as_pem, generate_private_key, generate_self_signed_app_certificate
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

MODES = {"None": ua.MessageSecurityMode.None_, "Sign": ua.MessageSecurityMode.Sign,
         "SignAndEncrypt": ua.MessageSecurityMode.SignAndEncrypt}
APPLICATION_URI = "urn:softplc:latency-client"


@dataclass(frozen=True)
class Security:
    """A parsed --security: the mode and, for Sign/SignAndEncrypt, the client certificate."""

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
        parts = [part.strip() for part in text.split(",")]
        mode = {name.lower(): name for name in MODES}.get(parts[0].lower().removeprefix("basic256sha256_"))
        if mode is None or len(parts) not in (1, 3):
            raise ValueError(f"bad --security {text!r}; write None, Sign or SignAndEncrypt, optionally followed by ,CERT,KEY")
        if len(parts) == 3:
            certificate, key = Path(parts[1]), Path(parts[2])
            for path in (certificate, key):
                if not path.is_file():
                    raise ValueError(f"--security: no such file {path}")
            return cls(mode, certificate, key)
        return cls(mode)


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
    data = certificate.read_bytes()
    loaded = x509.load_der_x509_certificate(data) if not data.startswith(b"-----") else x509.load_pem_x509_certificate(data)
    try:
        names = loaded.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return APPLICATION_URI
    uris = names.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else APPLICATION_URI
