"""The sync link's certificates: one self-signed pair per member, each pinned by the other (mutual TLS).

`softplc redundancy keys DIR --members a,b` makes both pairs once (`a.crt`/`a.key`, `b.crt`/
`b.key`); each machine keeps its own key and both certificates. A member accepts exactly one
certificate on the link — its peer's, compared byte for byte (SHA-256) after a TLS handshake that
already required it (TLS 1.3, client certificate mandatory): a stranger, or a member of another
pair, never gets as far as sending a message.
"""

from __future__ import annotations

import datetime
import hashlib
import os
import ssl
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

VALID_DAYS = 3650


def make_pair(directory: Path, name: str, plant: str = "softplc") -> tuple[Path, Path]:
    """Write NAME.crt and NAME.key (EC P-256, self-signed, 10 years) into `directory`; returns their paths."""
    directory.mkdir(parents=True, exist_ok=True)
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"{plant} redundancy {name}")])
    now = datetime.datetime.now(datetime.timezone.utc)
    certificate = (
        x509.CertificateBuilder().subject_name(subject).issuer_name(subject).public_key(key.public_key())
        .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.SubjectAlternativeName([x509.DNSName(f"softplc-{name}")]), critical=False)
        .sign(key, hashes.SHA256())
    )
    certificate_path, key_path = directory / f"{name}.crt", directory / f"{name}.key"
    certificate_path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    data = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    descriptor = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as file:
        file.write(data)
    return certificate_path, key_path


def fingerprint_of_der(der: bytes) -> str:
    return hashlib.sha256(der).hexdigest()


def fingerprint(path: Path) -> str:
    """The SHA-256 fingerprint of a PEM certificate file (what the peer pins)."""
    certificate = x509.load_pem_x509_certificate(path.read_bytes())
    return fingerprint_of_der(certificate.public_bytes(serialization.Encoding.DER))


def link_context(certificate: Path, key: Path, peer_certificate: Path, *, server: bool) -> ssl.SSLContext:
    """A TLS 1.3 context presenting this member's certificate and trusting only the peer's."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER if server else ssl.PROTOCOL_TLS_CLIENT)
    context.minimum_version = ssl.TLSVersion.TLSv1_3
    context.load_cert_chain(str(certificate), str(key))
    context.load_verify_locations(cafile=str(peer_certificate))
    context.check_hostname = False  # the peer is identified by its pinned certificate, not a host name
    context.verify_mode = ssl.CERT_REQUIRED
    return context
