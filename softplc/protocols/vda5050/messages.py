"""Building and reading VDA 5050 messages (2.0, 2.1): what the master sends, what a vehicle reports.

    header = Headers(version, manufacturer, serial).next(ORDER, now)              # headerId per topic, counted
    order = {**header, "orderId": "o-1", "orderUpdateId": 0, "nodes": [node(...)], "edges": [edge(...)]}
    state = VehicleState.from_message(decode(payload, "state", "2.1"))            # the fields the master uses
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

from softplc.protocols.vda5050.topics import VERSIONS


def timestamp(seconds: float) -> str:
    """ISO 8601 in UTC as the spec writes it: 2017-04-15T11:40:03.12Z (§6.4)."""
    moment = datetime.fromtimestamp(seconds, timezone.utc)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 10000:02d}Z"


class Headers:
    """The protocol header of one sender to one vehicle: `headerId` counts per topic (§6.4)."""

    def __init__(self, version: str, manufacturer: str, serial_number: str) -> None:
        self.version = VERSIONS[version]
        self.manufacturer = manufacturer
        self.serial_number = serial_number
        self._ids: dict[str, int] = {}

    def next(self, topic_name: str, now: float) -> dict[str, Any]:
        header_id = self._ids.get(topic_name, -1) + 1
        self._ids[topic_name] = header_id % 4294967296
        return {"headerId": self._ids[topic_name], "timestamp": timestamp(now), "version": self.version,
                "manufacturer": self.manufacturer, "serialNumber": self.serial_number}


def action(action_type: str, action_id: str, blocking_type: str = "NONE", parameters: dict[str, Any] | None = None,
           description: str = "") -> dict[str, Any]:
    """An action for a node, an edge or instantActions (§6.6.6); parameters as key/value pairs (§7.2)."""
    result: dict[str, Any] = {"actionType": action_type, "actionId": action_id, "blockingType": blocking_type}
    if description:
        result["actionDescription"] = description
    if parameters:
        result["actionParameters"] = [{"key": key, "value": value} for key, value in parameters.items()]
    return result


def node(node_id: str, sequence_id: int, released: bool, x: float, y: float, map_id: str, *, theta: float | None = None,
         deviation: float | None = None, actions: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    position: dict[str, Any] = {"x": x, "y": y, "mapId": map_id}
    if theta is not None:
        position["theta"] = math.atan2(math.sin(theta), math.cos(theta))
    if deviation is not None:
        position["allowedDeviationXY"] = deviation
    return {"nodeId": node_id, "sequenceId": sequence_id, "released": released, "nodePosition": position, "actions": actions or []}


def edge(edge_id: str, sequence_id: int, released: bool, start_node: str, end_node: str, *, max_speed: float | None = None,
         length: float | None = None, actions: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    result: dict[str, Any] = {"edgeId": edge_id, "sequenceId": sequence_id, "released": released, "startNodeId": start_node,
                              "endNodeId": end_node, "actions": actions or []}
    if max_speed is not None:
        result["maxSpeed"] = max_speed
    if length is not None:
        result["length"] = length
    return result


def parameters(an_action: dict[str, Any]) -> dict[str, Any]:
    """An action's parameters as a dict (unusable entries skipped)."""
    found = {}
    for item in an_action.get("actionParameters") or []:
        if isinstance(item, dict) and isinstance(item.get("key"), str):
            found[item["key"]] = item.get("value")
    return found


def instant_actions_of(message: dict[str, Any]) -> list[dict[str, Any]]:
    """The actions of an instantActions message: `actions` (released schemas) or `instantActions` (vda-5050-lib's 2.0 draft key)."""
    actions = message.get("actions")
    if actions is None:
        actions = message.get("instantActions")
    return [item for item in actions if isinstance(item, dict)] if isinstance(actions, list) else []


@dataclass(frozen=True)
class VehicleError:
    """One entry of a state's `errors` (§6.10.5)."""

    type: str
    level: str  # WARNING or FATAL
    description: str = ""
    hint: str = ""
    references: tuple[tuple[str, str], ...] = ()

    @property
    def text(self) -> str:
        """What an operator reads: 'orderError: start node too far (WARNING)'."""
        words = self.type + (f": {self.description}" if self.description else "")
        return f"{words} ({self.level})" + (f"; hint: {self.hint}" if self.hint else "")

    def reference(self, key: str) -> str | None:
        for reference_key, value in self.references:
            if reference_key == key:
                return value
        return None


@dataclass
class VehicleState:
    """The fields of a (schema-checked) state message the master control uses."""

    order_id: str
    order_update_id: int
    last_node_id: str
    last_node_sequence_id: int
    node_states: list[tuple[str, int, bool]]  # nodeId, sequenceId, released: what is still to be traversed
    edge_states: list[tuple[str, int, bool]]
    driving: bool
    operating_mode: str
    battery_charge: float
    charging: bool
    e_stop: str
    field_violation: bool
    errors: list[VehicleError] = field(default_factory=list)
    action_states: dict[str, str] = field(default_factory=dict)  # actionId → actionStatus
    action_types: dict[str, str] = field(default_factory=dict)
    paused: bool = False
    new_base_request: bool = False
    position: tuple[float, float, float] | None = None  # x, y, theta of an initialized position
    map_id: str = ""
    speed: float = 0.0
    loads: int | None = None  # None: the vehicle does not report loads
    header_id: int = 0

    @classmethod
    def from_message(cls, message: dict[str, Any]) -> VehicleState:
        position = message.get("agvPosition")
        pose = None
        if isinstance(position, dict) and position.get("positionInitialized"):
            pose = (float(position["x"]), float(position["y"]), float(position["theta"]))
        velocity = message.get("velocity") or {}
        errors = [
            VehicleError(item["errorType"], item["errorLevel"], item.get("errorDescription", ""), item.get("errorHint", ""),
                         tuple((ref["referenceKey"], ref["referenceValue"]) for ref in item.get("errorReferences") or []))
            for item in message["errors"]
        ]
        loads = message.get("loads")
        return cls(
            order_id=message["orderId"],
            order_update_id=message["orderUpdateId"],
            last_node_id=message["lastNodeId"],
            last_node_sequence_id=message["lastNodeSequenceId"],
            node_states=[(item["nodeId"], item["sequenceId"], item["released"]) for item in message["nodeStates"]],
            edge_states=[(item["edgeId"], item["sequenceId"], item["released"]) for item in message["edgeStates"]],
            driving=message["driving"],
            operating_mode=message["operatingMode"],
            battery_charge=float(message["batteryState"]["batteryCharge"]),
            charging=message["batteryState"]["charging"],
            e_stop=message["safetyState"]["eStop"],
            field_violation=message["safetyState"]["fieldViolation"],
            errors=errors,
            action_states={item["actionId"]: item["actionStatus"] for item in message["actionStates"]},
            action_types={item["actionId"]: item.get("actionType", "") for item in message["actionStates"]},
            paused=bool(message.get("paused", False)),
            new_base_request=bool(message.get("newBaseRequest", False)),
            position=pose,
            map_id=str(position.get("mapId", "")) if isinstance(position, dict) else "",
            speed=math.hypot(float(velocity.get("vx", 0.0)), float(velocity.get("vy", 0.0))),
            loads=len(loads) if isinstance(loads, list) else None,
            header_id=message["headerId"],
        )


@dataclass(frozen=True)
class FactsheetSummary:
    """What the robot–task compatibility needs of a factsheet (§6.15): size, speeds, load, actions."""

    series_name: str = ""
    length_mm: float | None = None
    width_mm: float | None = None
    height_mm: float | None = None
    max_linear_speed: float | None = None
    max_angular_speed: float | None = None
    max_load_mass: float | None = None
    actions: tuple[str, ...] = ()

    @classmethod
    def from_message(cls, message: dict[str, Any]) -> FactsheetSummary:
        """The usable parts of a factsheet (missing or mistyped ones stay None)."""
        physical = message.get("physicalParameters") if isinstance(message.get("physicalParameters"), dict) else {}
        kind = message.get("typeSpecification") if isinstance(message.get("typeSpecification"), dict) else {}
        features = message.get("protocolFeatures") if isinstance(message.get("protocolFeatures"), dict) else {}

        def number(section: dict[str, Any], key: str, scale: float = 1.0) -> float | None:
            value = section.get(key)
            return float(value) * scale if isinstance(value, (int, float)) and not isinstance(value, bool) else None

        actions = tuple(str(item["actionType"]) for item in features.get("agvActions") or []
                        if isinstance(item, dict) and isinstance(item.get("actionType"), str))
        return cls(
            series_name=str(kind.get("seriesName", "")),
            length_mm=number(physical, "length", 1000.0),
            width_mm=number(physical, "width", 1000.0),
            height_mm=number(physical, "heightMax", 1000.0),
            max_linear_speed=number(physical, "speedMax"),
            max_angular_speed=number(physical, "angularSpeedMax"),
            max_load_mass=number(kind, "maxLoadMass"),
            actions=actions,
        )
