"""Where a client command connects: an `--endpoint` checked as it is parsed, a redundant pair's members from its configuration.

The rest of the choice (the configuration's `servers.opcua`, the default) is `where()` in
`softplc/clients/login.py`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/softplc/"
DEFAULT_CONFIG = "tagdb.yaml"


def endpoint_url(text: str) -> str:
    """An `--endpoint` argument: opc.tcp://HOST[:PORT][/PATH], else argparse's error saying what is wrong."""
    from urllib.parse import urlsplit

    url = text.strip()
    parts = urlsplit(url)
    problem = None
    if "://" not in url:
        problem = "no scheme"
    elif parts.scheme.lower() in ("http", "https"):
        problem = f"{parts.scheme.lower()}:// is the address of a web page (the HMI), not of an OPC UA server"
    elif parts.scheme.lower() != "opc.tcp":
        problem = f"the scheme is {parts.scheme}://"
    elif not parts.hostname:
        problem = "no host"
    else:
        try:
            parts.port  # noqa: B018 — raises for a port that is not a number from 0 to 65535
        except ValueError:
            port = parts.netloc.rpartition(":")[2]
            problem = f"{port!r} is not a port number"
    if problem is not None:
        raise argparse.ArgumentTypeError(f"{text!r} is not an OPC UA endpoint ({problem}): write opc.tcp://HOST:PORT/PATH, e.g. {DEFAULT_ENDPOINT}")
    return url


def endpoint_urls(text: str) -> str:
    """An `--endpoint` argument naming one endpoint or a redundant pair's, comma separated; each checked like `endpoint_url`."""
    return ",".join(endpoint_url(part) for part in text.split(",") if part.strip()) or endpoint_url(text)


def pair_endpoints(config: str | None) -> str | None:
    """The members' OPC UA endpoints of a redundant pair's configuration, comma separated (None: not a pair)."""
    from softplc.config.yamlsource import ConfigError, load_yaml

    path = Path(config or DEFAULT_CONFIG)
    if not path.is_file():
        return None
    try:
        data, _ = load_yaml(path)
    except (ConfigError, OSError):
        return None
    section = data.get("redundancy") if isinstance(data, dict) else None
    members = section.get("members") if isinstance(section, dict) else None
    if not isinstance(members, dict):
        return None
    endpoints = [reachable(entry.get("opcua")) for entry in members.values() if isinstance(entry, dict)]
    return ",".join(endpoint for endpoint in endpoints if endpoint) or None


def reachable(endpoint: object) -> str | None:
    """A configured endpoint as a client here reaches it: a server listening everywhere is reached on loopback."""
    if not isinstance(endpoint, str) or not endpoint.strip():
        return None
    endpoint = endpoint.strip()
    for wildcard in ("0.0.0.0", "[::]"):
        endpoint = endpoint.replace(f"//{wildcard}:", "//127.0.0.1:")
    return endpoint
