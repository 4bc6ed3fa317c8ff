"""`--endpoint` as the user writes it, checked before anything starts.

OPC UA: `opc.tcp://HOST:PORT[/PATH]`. Modbus TCP: `HOST:PORT`, also `modbus://HOST:PORT` or
`tcp://HOST:PORT` (a trailing `/` is ignored); an IPv6 host is written in brackets, `[::1]:502`.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlsplit

HOW = "write opc.tcp://HOST:PORT[/PATH] for OPC UA, HOST:PORT (or modbus://HOST:PORT) for Modbus TCP"
MODBUS_SCHEMES = ("modbus://", "tcp://")


class EndpointError(ValueError):
    """An --endpoint that names no host and port of the protocol; the message says what is wrong."""


@dataclass(frozen=True)
class Endpoint:
    protocol: str  # opcua | modbus
    host: str  # without IPv6 brackets
    port: int
    text: str  # as given (the OPC UA client gets the URL unchanged)


def guess_protocol(text: str) -> str:
    """opcua for an opc.tcp:// URL, modbus for anything else."""
    return "opcua" if text.strip().lower().startswith("opc.tcp://") else "modbus"


def parse_endpoint(text: str, protocol: str | None = None) -> Endpoint:
    """The endpoint of `protocol` (guessed from the text when None); raises EndpointError."""
    protocol = protocol or guess_protocol(text)
    if protocol == "opcua":
        return _opcua(text)
    return _modbus(text)


def _opcua(text: str) -> Endpoint:
    if not text.lower().startswith("opc.tcp://"):
        raise EndpointError(f"--endpoint {text!r} is no OPC UA endpoint: {HOW}")
    parts = urlsplit(text)
    try:
        port = parts.port
    except ValueError:
        raise EndpointError(f"--endpoint {text!r}: the port must be a number from 1 to 65535") from None
    if not parts.hostname:
        raise EndpointError(f"--endpoint {text!r} names no host: write opc.tcp://HOST:PORT[/PATH]")
    if port is None:
        raise EndpointError(f"--endpoint {text!r} names no port: write opc.tcp://HOST:PORT[/PATH], e.g. opc.tcp://{parts.hostname}:4840/")
    return Endpoint("opcua", parts.hostname, _port(port, text), text)


def _modbus(text: str) -> Endpoint:
    rest = text.strip()
    for scheme in MODBUS_SCHEMES:
        if rest.lower().startswith(scheme):
            rest = rest[len(scheme):]
            break
    else:
        if "://" in rest:
            raise EndpointError(f"--endpoint {text!r}: unknown scheme {rest.split('://')[0]}://; {HOW}")
    rest = rest.rstrip("/")
    host, colon, port = rest.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not colon or not host or not port.isdigit():
        raise EndpointError(f"--endpoint {text!r} is no HOST:PORT: {HOW}")
    if "/" in host or any(c.isspace() for c in host):
        raise EndpointError(f"--endpoint {text!r}: {host!r} is no host name; {HOW}")
    return Endpoint("modbus", host, _port(int(port), text), text)


def _port(port: int, text: str) -> int:
    if not 1 <= port <= 65535:
        raise EndpointError(f"--endpoint {text!r}: the port must be a number from 1 to 65535")
    return port
