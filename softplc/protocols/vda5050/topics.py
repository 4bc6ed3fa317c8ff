"""VDA 5050 MQTT topics: `interfaceName/majorVersion/manufacturer/serialNumber/topic` (spec 2.1 §6.3).

    topic("uagv", "2.1", "acme", "001", ORDER) == "uagv/v2/acme/001/order"
    parse("uagv/v2/acme/001/state", "uagv", "2.0") == VehicleTopic("acme", "001", "state")
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ORDER = "order"
INSTANT_ACTIONS = "instantActions"
STATE = "state"
VISUALIZATION = "visualization"
CONNECTION = "connection"
FACTSHEET = "factsheet"
MASTER_TOPICS = (ORDER, INSTANT_ACTIONS)  # published by the master control
VEHICLE_TOPICS = (STATE, VISUALIZATION, CONNECTION, FACTSHEET)  # published by a vehicle

# The protocol versions this package speaks: configuration name → the version sent in headers.
VERSIONS = {"2.0": "2.0.0", "2.1": "2.1.0"}
DEFAULT_VERSION = "2.0"
DEFAULT_INTERFACE = "uagv"

# Characters the spec recommends for ids and serial numbers (§6.1.2, §6.3); '/', '+', '#' and '$' never.
ID_PATTERN = r"^[A-Za-z0-9_.:-]+$"
_ID = re.compile(ID_PATTERN)


def major(version: str) -> str:
    """The topic level of a version: '2.1' → 'v2'."""
    return "v" + version.split(".")[0]


def is_topic_name(text: str) -> bool:
    """True when `text` may stand in a topic level (manufacturer, serial number)."""
    return bool(_ID.match(text))


def topic(interface: str, version: str, manufacturer: str, serial_number: str, name: str) -> str:
    return f"{interface}/{major(version)}/{manufacturer}/{serial_number}/{name}"


def vehicle_filter(interface: str, version: str, name: str) -> str:
    """The subscription that receives topic `name` of every vehicle."""
    return f"{interface}/{major(version)}/+/+/{name}"


@dataclass(frozen=True)
class VehicleTopic:
    manufacturer: str
    serial_number: str
    name: str


def parse(text: str, interface: str, version: str) -> VehicleTopic | None:
    """The vehicle and topic name of `text`, or None when it is not a topic of this interface and version."""
    parts = text.split("/")
    if len(parts) != 5 or parts[0] != interface or parts[1] != major(version):
        return None
    return VehicleTopic(parts[2], parts[3], parts[4])
