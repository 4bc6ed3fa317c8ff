"""The Sparkplug B topic namespace (specification §4.1): `spBv1.0/<group>/<type>/<edge node>[/<device>]`.

The primary host application's state is on `spBv1.0/STATE/<host id>`: retained JSON
`{"online": true|false, "timestamp": <ms since the epoch>}` (§4.3 and §5.4).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

NAMESPACE = "spBv1.0"
RESERVED = ("+", "/", "#")  # never in a group, edge node, device or host id (§4.1.2–4.1.5)
NODE_TYPES = ("NBIRTH", "NDEATH", "NDATA", "NCMD")
DEVICE_TYPES = ("DBIRTH", "DDEATH", "DDATA", "DCMD")


def id_problem(text: object, what: str) -> str | None:
    """Why `text` cannot be a Sparkplug id (group, edge node, device, host), or None."""
    if not isinstance(text, str) or not text:
        return f"{what} must be a non-empty text"
    bad = [character for character in RESERVED if character in text]
    if bad:
        return f"{what} {text!r} contains {bad[0]!r}: Sparkplug ids may not contain + / or #"
    return None


def node_topic(group: str, message_type: str, edge_node: str) -> str:
    return f"{NAMESPACE}/{group}/{message_type}/{edge_node}"


def device_topic(group: str, message_type: str, edge_node: str, device: str) -> str:
    return f"{NAMESPACE}/{group}/{message_type}/{edge_node}/{device}"


def state_topic(host: str) -> str:
    return f"{NAMESPACE}/STATE/{host}"


def command_target(topic: str, group: str, edge_node: str) -> tuple[str, str | None] | None:
    """("NCMD", None) or ("DCMD", device) for a command to this edge node's topic; None for any other topic."""
    parts = topic.split("/")
    if len(parts) < 4 or parts[0] != NAMESPACE or parts[1] != group or parts[3] != edge_node:
        return None
    if parts[2] == "NCMD" and len(parts) == 4:
        return "NCMD", None
    if parts[2] == "DCMD" and len(parts) == 5 and parts[4]:
        return "DCMD", parts[4]
    return None


@dataclass(frozen=True)
class HostState:
    """A primary host application's STATE message."""

    online: bool
    timestamp: int  # ms since the epoch, UTC: the host's connect time


def parse_state(payload: bytes) -> HostState:
    """A STATE payload; ValueError (with what is wrong) for anything but the 3.0.0 JSON form."""
    try:
        document = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"not JSON: {error}") from None
    if not isinstance(document, dict):
        raise ValueError("not a JSON object")
    online, timestamp = document.get("online"), document.get("timestamp")
    if not isinstance(online, bool):
        raise ValueError("'online' is missing or not true/false")
    if isinstance(timestamp, bool) or not isinstance(timestamp, (int, float)) or timestamp < 0:
        raise ValueError("'timestamp' is missing or not a number of milliseconds")
    return HostState(online, int(timestamp))


def state_payload(online: bool, timestamp: int) -> bytes:
    """A STATE payload (what a host publishes; the tests' host uses it)."""
    return json.dumps({"online": online, "timestamp": timestamp}).encode()
