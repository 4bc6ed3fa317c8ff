"""The `vda5050:` section of tagdb.yaml: its schema, its checks, and the tags and alarms it adds per vehicle.

    vda5050:
      roadmap: robots/roadmap.yaml   # the navigation graph orders are made of (softplc/robotics/roadmap.py)
      interface: uagv                # the first topic level (default uagv)
      version: "2.0"                 # VDA 5050 protocol version: "2.0" or "2.1"
      lost_after: 60s                # no state for this long: the vehicle is lost (tags BAD, its task re-dispatched)
      ack_timeout: 2s                # an order the vehicle's state has not acknowledged is re-sent identically
      lookahead: 2                   # nodes released ahead of each vehicle (the rest of its route is the horizon)
      make_way: true                 # idle vehicles standing in another's way are moved to a free node

Per VDA 5050 robot (driver: vda5050 in robots.yaml) the section adds `_sys.vda5050.<id>.*` tags
(connection, order, base, horizon, error, rejected, battery, mode, estop, paused, waiting) and two
alarms (the vehicle's own error text; a rejected order), plus `_sys.vda5050.broker` and its alarm.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.config.schema import DURATION, Section
from softplc.core.datatypes import DataType
from softplc.core.tags import Access, TagDef

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SCHEMA: dict[str, Any] = {
    "description": "VDA 5050 master control of the fleet's driver: vda5050 robots over the mqtt: broker (docs/vda5050.md).",
    "type": "object",
    "properties": {
        "roadmap": {"type": "string", "description": "Roadmap file, relative to this one (default robots/roadmap.yaml)."},
        "interface": {"type": "string", "pattern": r"^[A-Za-z0-9_.:-]+$", "description": "interfaceName topic level (default uagv)."},
        "version": {"enum": ["2.0", "2.1"], "description": "VDA 5050 protocol version (default 2.0)."},
        "lost_after": DURATION,
        "ack_timeout": DURATION,
        "tick": DURATION,
        "lookahead": {"type": "integer", "minimum": 1, "maximum": 100, "description": "Nodes released ahead of a vehicle (default 2)."},
        "make_way": {"type": "boolean", "description": "Move idle vehicles out of another's way (default true)."},
    },
    "additionalProperties": False,
}

BROKER_TAG = "_sys.vda5050.broker"
STRING_TAGS = {
    "connection": "the vehicle's last connection message: ONLINE, OFFLINE, CONNECTIONBROKEN ('' before any)",
    "order": "the order the master gave it: orderId/orderUpdateId",
    "base": "released nodes still to be traversed (the base), space-separated",
    "horizon": "planned nodes not yet released (the horizon)",
    "error": "the vehicle's active errors, in its own words ('' when none)",
    "rejected": "why the vehicle rejected the master's last order ('' when it took it)",
    "mode": "operatingMode: AUTOMATIC, SEMIAUTOMATIC, MANUAL, SERVICE or TEACHIN",
    "estop": "safetyState.eStop: NONE, AUTOACK, MANUAL or REMOTE",
    "waiting": "what the traffic control holds it back for ('' when free to go)",
}


def vehicle_ids(config: PlantConfig) -> list[str]:
    """The ids of the VDA 5050 robots of the plant's robots file ([] when it cannot be read: the fleet section says why)."""
    from softplc.config.yamlsource import ConfigError
    from softplc.robotics.layout import fleet_files
    from softplc.robotics.robots import DriverKind, load_robots

    path = fleet_files(config)["robots"]
    if not path.is_file():
        return []
    try:
        return [robot.id for robot in load_robots(path) if robot.driver is DriverKind.VDA5050]
    except ConfigError:
        return []


def tags(config: PlantConfig) -> list[TagDef]:
    if config.section("vda5050") is None:
        return []
    found = [TagDef(BROKER_TAG, DataType.BOOL, False, description="the MQTT broker of the VDA 5050 vehicles is reachable",
                    access=Access.RO, runtime_only=True, group="Diagnostics/VDA5050")]
    for robot_id in vehicle_ids(config):
        prefix = f"_sys.vda5050.{robot_id}"
        group = f"Diagnostics/VDA5050/{robot_id}"
        found += [TagDef(f"{prefix}.{name}", DataType.STRING, "", description=text, access=Access.RO, runtime_only=True, group=group)
                  for name, text in STRING_TAGS.items()]
        found += [
            TagDef(f"{prefix}.battery", DataType.FLOAT64, 0.0, unit="%", description="batteryState.batteryCharge",
                   access=Access.RO, runtime_only=True, group=group),
            TagDef(f"{prefix}.paused", DataType.BOOL, False, description="paused (a startPause or a button on the vehicle)",
                   access=Access.RO, runtime_only=True, group=group),
            TagDef(f"{prefix}.resends", DataType.UINT32, 0, description="orders sent again because no state acknowledged them",
                   access=Access.RO, runtime_only=True, group=group),
        ]
    return found


def alarms(config: PlantConfig) -> list[tuple[tuple[str | int, ...], dict[str, Any]]]:
    if config.section("vda5050") is None:
        return []
    found: list[tuple[tuple[str | int, ...], dict[str, Any]]] = [(("vda5050",), {
        "name": "vda5050_broker_down", "discrete": {"tag": BROKER_TAG, "value": False}, "priority": "high", "on_delay": "3s",
        "message": "the MQTT broker of the VDA 5050 vehicles is unreachable: their tags are BAD until it is back",
    })]
    for robot_id in vehicle_ids(config):
        prefix = f"_sys.vda5050.{robot_id}"
        found.append((("vda5050",), {"name": f"{robot_id}_vehicle_error", "discrete": {"tag": f"{prefix}.error", "normal": ""},
                                      "priority": "high", "message": f"{robot_id} reports: {{{prefix}.error}}"}))
        found.append((("vda5050",), {"name": f"{robot_id}_order_rejected", "discrete": {"tag": f"{prefix}.rejected", "normal": ""},
                                      "priority": "high", "message": f"{robot_id} rejected its order: {{{prefix}.rejected}}"}))
    return found


def problems(config: PlantConfig) -> list[Problem]:
    """Durations that are not positive, and the roadmap file's own problems (located in that file)."""
    section = config.section("vda5050")
    if section is None:
        return []
    from softplc.adapters.vda5050.settings import DURATIONS, VdaSettings
    from softplc.config.yamlsource import ConfigError
    from softplc.robotics.roadmap import load_roadmap
    from softplc.util.durations import parse_duration

    found = []
    for key in DURATIONS:
        if key in section:
            try:
                seconds = parse_duration(section[key])
            except (TypeError, ValueError) as error:
                found.append(config.problem(("vda5050", key), f"bad {key} {section[key]!r}: {error}"))
                continue
            if seconds <= 0:
                found.append(config.problem(("vda5050", key), f"{key} must be greater than zero"))
    if found:
        return found
    roadmap = VdaSettings.from_config(config).roadmap
    if not roadmap.is_file():
        where = ("vda5050", "roadmap") if "roadmap" in section else ("vda5050",)
        return [config.problem(where, f"roadmap file not found: {roadmap}")]
    try:
        load_roadmap(roadmap)
    except ConfigError as error:
        return list(error.problems)
    return []


SECTION = Section(path=("vda5050",), schema=SCHEMA, problems=problems, tags=tags, alarms=alarms)
