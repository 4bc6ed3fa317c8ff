"""Host names and port numbers as every server's settings and flags take them (nothing is looked up)."""

from __future__ import annotations

import argparse
import ipaddress
import re

_HOST_LABEL = re.compile(r"^[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?$")


def is_host(text: str) -> bool:
    """An IP address or a syntactically valid host name (RFC 1123); nothing is looked up."""
    try:
        ipaddress.ip_address(text)
        return True
    except ValueError:
        pass
    labels = text.removesuffix(".").split(".")
    return 0 < len(text) <= 253 and all(_HOST_LABEL.match(label) for label in labels)


def host_name(text: str) -> str:
    """argparse type for a --*-host flag."""
    if not is_host(text):
        raise argparse.ArgumentTypeError(f"not an IP address or host name: {text!r}")
    return text


def port_number(text: str) -> int:
    """argparse type for a --*-port flag: an integer 0..65535 (0 = any free port)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port {port} is outside 0..65535")
    return port
