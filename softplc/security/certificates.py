"""Certificates: the server's own (made on first start), and the trust list for client certificates.

The PKI directory (default `<state_dir>/pki`) holds:

    own/cert.der, own/key.pem   the server's certificate and private key (key readable by owner only)
    trusted/                    client certificates allowed to open a Sign/SignAndEncrypt session
    rejected/                   certificates that were refused (copy one to trusted/ to allow it:
                                `softplc opcua trust FINGERPRINT`)

A certificate is trusted when its SHA-256 fingerprint equals that of a file in trusted/ and it
is inside its validity period. The directory is re-read when it changes, so trusting a
certificate takes effect without a restart.
"""

from __future__ import annotations

import datetime
import ipaddress
import logging
import os
import re
import socket
from dataclasses import dataclass
from pathlib import Path

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.cert_gen import dump_private_key_as_pem, generate_private_key, generate_self_signed_app_certificate
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from softplc.security.users import fingerprint, normalise_fingerprint

log = logging.getLogger(__name__)

CERT_VALID_DAYS = 5 * 365


def load_certificate_file(path: Path) -> x509.Certificate:
    """Read a PEM or DER certificate file; raise ValueError with a clear message."""
    data = path.read_bytes()
    try:
        if b"-----BEGIN CERTIFICATE-----" in data:
            return x509.load_pem_x509_certificate(data)
        return x509.load_der_x509_certificate(data)
    except ValueError as error:
        raise ValueError(f"{path}: not a PEM or DER certificate ({error})") from None


def der_bytes(certificate: x509.Certificate) -> bytes:
    return certificate.public_bytes(serialization.Encoding.DER)


def common_name(certificate: x509.Certificate) -> str:
    names = certificate.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(names[0].value) if names else certificate.subject.rfc4514_string()


@dataclass(frozen=True)
class CertificateInfo:
    """A certificate as listed by `softplc opcua certs`."""

    path: Path
    fingerprint: str
    subject: str
    not_after: datetime.datetime


def describe_file(path: Path) -> CertificateInfo | None:
    try:
        certificate = load_certificate_file(path)
    except (OSError, ValueError):
        return None
    return CertificateInfo(path, fingerprint(der_bytes(certificate)), common_name(certificate), certificate.not_valid_after_utc)


class Pki:
    """The server's PKI directory: own certificate and key, trusted and rejected client certificates."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.own_dir = root / "own"
        self.trusted_dir = root / "trusted"
        self.rejected_dir = root / "rejected"
        self.certificate_path = self.own_dir / "cert.der"
        self.key_path = self.own_dir / "key.pem"
        self._trusted_cache: tuple[int, frozenset[str]] | None = None

    def ensure_dirs(self) -> None:
        for directory in (self.own_dir, self.trusted_dir, self.rejected_dir):
            directory.mkdir(parents=True, exist_ok=True)
        os.chmod(self.own_dir, 0o700)

    # -- the server's own certificate ---------------------------------------------------

    def own_identity(self, application_uri: str, hostnames: list[str]) -> tuple[x509.Certificate, rsa.RSAPrivateKey]:
        """The server's certificate and private key, loaded (made first when missing or expired).

        The key is the one this PKI made and keeps readable by its owner only, so the RSA key
        checks that guard against a key from elsewhere (~40 ms of a start for 2048 bits) are skipped.
        """
        certificate_path, key_path = self.ensure_server_certificate(application_uri, hostnames)
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None, unsafe_skip_rsa_key_validation=True)
        if not isinstance(key, rsa.RSAPrivateKey):
            raise ValueError(f"{key_path}: not an RSA private key (delete {self.own_dir} to make a new one)")
        return load_certificate_file(certificate_path), key

    def ensure_server_certificate(self, application_uri: str, hostnames: list[str]) -> tuple[Path, Path]:
        """Return (certificate, key) paths, generating them on first start or when expired."""
        self.ensure_dirs()
        if self.certificate_path.exists() and self.key_path.exists():
            certificate = load_certificate_file(self.certificate_path)
            if certificate.not_valid_after_utc > datetime.datetime.now(datetime.timezone.utc):
                uris = _uris(certificate)
                if application_uri not in uris:
                    log.warning("server certificate %s is for %s, not %s; clients may complain "
                                "(delete %s to make a new one)", self.certificate_path, uris, application_uri, self.own_dir)
                return self.certificate_path, self.key_path
            log.warning("server certificate %s expired on %s; making a new one (clients must trust it again)",
                        self.certificate_path, certificate.not_valid_after_utc.date())
        key = generate_private_key()
        names: list[x509.GeneralName] = [x509.UniformResourceIdentifier(application_uri)]
        for host in dict.fromkeys([*hostnames, socket.gethostname(), "localhost"]):
            names.append(_host_name(host))
            if isinstance(names[-1], x509.IPAddress):
                names.append(x509.DNSName(host))  # many OPC UA stacks look only at DNS names
        certificate = generate_self_signed_app_certificate(
            key, "softplc OPC UA server", {"organizationName": "softplc"}, names,
            extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH], days=CERT_VALID_DAYS,
        )
        _write_private(self.key_path, dump_private_key_as_pem(key))
        self.certificate_path.write_bytes(der_bytes(certificate))
        log.info("made server certificate %s (SHA-256 %s)", self.certificate_path, fingerprint(der_bytes(certificate)))
        return self.certificate_path, self.key_path

    # -- client certificates ------------------------------------------------------------

    def trusted_fingerprints(self) -> frozenset[str]:
        """Fingerprints of the certificates in trusted/ (re-read when the directory changes)."""
        try:
            stamp = self.trusted_dir.stat().st_mtime_ns
        except FileNotFoundError:
            return frozenset()
        if self._trusted_cache is None or self._trusted_cache[0] != stamp:
            prints = {info.fingerprint for info in self.list(self.trusted_dir)}
            self._trusted_cache = (stamp, frozenset(prints))
        return self._trusted_cache[1]

    def is_trusted(self, der: bytes) -> bool:
        return fingerprint(der) in self.trusted_fingerprints()

    def reject(self, certificate: x509.Certificate) -> Path:
        """Keep a refused certificate in rejected/ so an administrator can trust it later."""
        self.rejected_dir.mkdir(parents=True, exist_ok=True)
        der = der_bytes(certificate)
        path = self.rejected_dir / f"{_safe(common_name(certificate))}_{fingerprint(der)[:16]}.der"
        if not path.exists():
            path.write_bytes(der)
        return path

    def list(self, directory: Path) -> list[CertificateInfo]:
        if not directory.is_dir():
            return []
        infos = [describe_file(path) for path in sorted(directory.iterdir()) if path.is_file()]
        return [info for info in infos if info is not None]

    def trust(self, what: str) -> Path:
        """Trust a certificate file, or a rejected certificate by fingerprint (prefix); return its path."""
        self.ensure_dirs()
        candidate = Path(what)
        if candidate.is_file():
            certificate = load_certificate_file(candidate)
            der = der_bytes(certificate)
        else:
            wanted = normalise_fingerprint(what)
            if len(wanted) < 8:
                raise ValueError(f"'{what}' is neither a certificate file nor a fingerprint (give at least 8 hex digits)")
            matches = [info for info in self.list(self.rejected_dir) + self.list(self.trusted_dir) if info.fingerprint.startswith(wanted)]
            distinct = {info.fingerprint for info in matches}
            if not distinct:
                raise ValueError(f"no rejected certificate has fingerprint {wanted}…; see `softplc opcua certs`")
            if len(distinct) > 1:
                raise ValueError(f"fingerprint {wanted}… is ambiguous; give more digits")
            info = matches[0]
            if info.path.parent == self.trusted_dir:
                return info.path
            certificate = load_certificate_file(info.path)
            der = der_bytes(certificate)
        target = self.trusted_dir / f"{_safe(common_name(certificate))}_{fingerprint(der)[:16]}.der"
        target.write_bytes(der)
        for info in self.list(self.rejected_dir):
            if info.fingerprint == fingerprint(der):
                info.path.unlink()
        return target

    def untrust(self, what: str) -> Path:
        """Move a trusted certificate (by fingerprint prefix) back to rejected/."""
        wanted = normalise_fingerprint(what)
        matches = [info for info in self.list(self.trusted_dir) if wanted and info.fingerprint.startswith(wanted)]
        if len({info.fingerprint for info in matches}) != 1:
            raise ValueError(f"no single trusted certificate has fingerprint {wanted}…; see `softplc opcua certs`")
        self.rejected_dir.mkdir(parents=True, exist_ok=True)
        target = self.rejected_dir / matches[0].path.name
        matches[0].path.replace(target)
        for info in matches[1:]:
            info.path.unlink()
        return target


class ClientCertificateValidator:
    """asyncua's certificate hook: only trusted, unexpired client certificates, issued for the
    ApplicationUri the client describes itself with, may open a session.

    `secured` tells whether a certificate came with a Sign/SignAndEncrypt channel; on a
    SecurityPolicy None channel the certificate proves nothing and is ignored (OPC UA Part 4).
    """

    def __init__(self, pki: Pki, secured: "SecuredChannels", *, all_secured: bool = False) -> None:
        self.pki = pki
        self.secured = secured
        self.all_secured = all_secured  # no None policy offered: every certificate is checked

    async def __call__(self, certificate: x509.Certificate, application: ua.ApplicationDescription) -> None:
        der = der_bytes(certificate)
        if not self.all_secured and not self.secured.seen(der):
            return
        now = datetime.datetime.now(datetime.timezone.utc)
        if not certificate.not_valid_before_utc <= now <= certificate.not_valid_after_utc:
            log.warning("refused client certificate %s (%s): outside its validity period", common_name(certificate), fingerprint(der)[:16])
            raise ServiceError(ua.StatusCodes.BadCertificateTimeInvalid)
        if not self.pki.is_trusted(der):
            path = self.pki.reject(certificate)
            log.warning("refused untrusted client certificate %s (SHA-256 %s), kept in %s; "
                        "trust it with: softplc opcua trust %s", common_name(certificate), fingerprint(der), path, fingerprint(der)[:16])
            raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)
        # Part 4, CreateSession: the certificate must be the client application's own (the URI in
        # its subjectAltName equals the ApplicationUri the client describes itself with). Checked
        # after trust, in the order of Part 4's certificate validation steps.
        claimed = application.ApplicationUri if application is not None else None
        uris = _uris(certificate)
        if claimed not in uris:
            log.warning("refused client certificate %s (%s): it is for %s, the client says it is %r", common_name(certificate),
                        fingerprint(der)[:16], ", ".join(uris) or "no application URI", claimed)
            raise ServiceError(ua.StatusCodes.BadCertificateUriInvalid)


class SecuredChannels:
    """Remembers the client certificates presented on secured channels (bounded)."""

    def __init__(self, limit: int = 1024) -> None:
        self._seen: dict[bytes, None] = {}
        self._limit = limit

    def add(self, der: bytes | None) -> None:
        if der:
            self._seen.pop(der, None)
            self._seen[der] = None
            while len(self._seen) > self._limit:
                del self._seen[next(iter(self._seen))]

    def seen(self, der: bytes) -> bool:
        return der in self._seen


def _uris(certificate: x509.Certificate) -> list[str]:
    try:
        san = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    except x509.ExtensionNotFound:
        return []
    return list(san.value.get_values_for_type(x509.UniformResourceIdentifier))


def _host_name(host: str) -> x509.GeneralName:
    try:
        return x509.IPAddress(ipaddress.ip_address(host))
    except ValueError:
        return x509.DNSName(host)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)[:40] or "certificate"


def _write_private(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as handle:
        handle.write(data)
