"""Credentials of the client process: an operator login on our runtime, and OPC UA client certificates."""

from __future__ import annotations

import logging
import secrets
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from softplc.latency.target import Target

log = logging.getLogger(__name__)


def with_opcua_login(target: Target, state_dir: Path) -> Target:
    """Our OPC UA server lets anonymous clients only read: give the client an operator login
    (and, for --security Sign/SignAndEncrypt, a client certificate the server trusts)."""
    from softplc.adapters.opcua import DEFAULT_NAMESPACE, Pki, Role, UserStore
    from softplc.latency.certificate import Security, make_client_certificate

    password = secrets.token_urlsafe(18)
    UserStore(state_dir / "users.yaml").add("latency", Role.OPERATOR, password)
    security = target.security
    if security:
        parsed = Security.parse(security)
        if parsed.secured:
            if parsed.certificate is None:
                certificate, key = make_client_certificate(state_dir / "client")
                parsed = Security(parsed.mode, certificate, key)
            assert parsed.certificate is not None
            Pki(state_dir / "pki").trust(str(parsed.certificate))
            security = parsed.text()
    return replace(target, user="latency", password=password, namespace=target.namespace or DEFAULT_NAMESPACE, security=security)


def client_security(target: Target) -> Target:
    """For --endpoint: a secured mode without a certificate uses ~/.softplc/latency-client (made once)."""
    if not target.security:
        return target
    # asyncua and cryptography come with certificate.py: imported only for a secured mode.
    from softplc.latency.certificate import Security, make_client_certificate

    parsed = Security.parse(target.security)
    if not parsed.secured or parsed.certificate is not None:
        return target
    directory = Path.home() / ".softplc" / "latency-client"
    certificate, key = directory / "latency-client.der", directory / "latency-client.pem"
    if not (certificate.is_file() and key.is_file()):
        certificate, key = make_client_certificate(directory)
        log.warning("made OPC UA client certificate %s: the server must trust it before a %s session opens", certificate, parsed.mode)
    return replace(target, security=Security(parsed.mode, certificate, key).text())
