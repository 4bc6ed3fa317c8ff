"""JSON Schemas of the VDA 5050 messages, 2.0 and 2.1, written from the spec's field tables.

Each table row became a property: its data type a JSON type (uint32 → integer 0…2³²−1, float64 →
number, enumerations → enum), a field not in italics → required. Where 2.1 differs from 2.0
the builder takes the version: corridors on edges, maps in the state and the map actions,
`errorHint`, the factsheet's `vehicleConfig` (2.1) and `localizationParameters` (2.0), the angular
speeds of `physicalParameters`. (The schema files in the spec's repository were not copied: they
are for reading, and the spec says its tables win where they differ.)

`schema(kind, version, closed=...)`: with `closed=True` no field outside the tables is allowed —
what the master checks its own messages with; vehicles' messages are read with `closed=False`,
since vendors add fields of their own.
"""

from __future__ import annotations

import functools
import math
from typing import Any

UINT32 = {"type": "integer", "minimum": 0, "maximum": 4294967295}
NUMBER = {"type": "number"}
NON_NEGATIVE = {"type": "number", "minimum": 0}
STRING = {"type": "string"}
BOOLEAN = {"type": "boolean"}
STRINGS = {"type": "array", "items": STRING}

ORDER_KIND, INSTANT_ACTIONS_KIND, STATE_KIND = "order", "instantActions", "state"
CONNECTION_KIND, FACTSHEET_KIND, VISUALIZATION_KIND = "connection", "factsheet", "visualization"
KINDS = (ORDER_KIND, INSTANT_ACTIONS_KIND, STATE_KIND, CONNECTION_KIND, FACTSHEET_KIND, VISUALIZATION_KIND)

BLOCKING_TYPES = ("NONE", "SOFT", "HARD")
ACTION_STATUSES = ("WAITING", "INITIALIZING", "RUNNING", "PAUSED", "FINISHED", "FAILED")
OPERATING_MODES = ("AUTOMATIC", "SEMIAUTOMATIC", "MANUAL", "SERVICE", "TEACHIN")
ERROR_LEVELS = ("WARNING", "FATAL")
INFO_LEVELS = ("DEBUG", "INFO")
E_STOPS = ("AUTOACK", "MANUAL", "REMOTE", "NONE")
CONNECTION_STATES = ("ONLINE", "OFFLINE", "CONNECTIONBROKEN")


def _object(required: dict[str, Any], optional: dict[str, Any] | None = None, *, closed: bool) -> dict[str, Any]:
    properties = {**required, **(optional or {})}
    return {"type": "object", "properties": properties, "required": list(required), "additionalProperties": not closed}


def _array(item: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": item}


def _header(closed: bool, *, optional_id_and_time: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    """The protocol header (§6.4): five fields at the top level of every message."""
    identity = {"headerId": UINT32, "timestamp": STRING}
    rest = {"version": STRING, "manufacturer": STRING, "serialNumber": STRING}
    if optional_id_and_time:  # the 2.0 factsheet: "only relevant for an automatic electronic transfer"
        return rest, identity
    return {**identity, **rest}, {}


def _message(body_required: dict[str, Any], body_optional: dict[str, Any] | None = None, *, closed: bool,
             optional_id_and_time: bool = False) -> dict[str, Any]:
    required, optional = _header(closed, optional_id_and_time=optional_id_and_time)
    schema = _object({**required, **body_required}, {**optional, **(body_optional or {})}, closed=closed)
    schema["$schema"] = "http://json-schema.org/draft-07/schema#"  # what fastjsonschema compiles (the keywords are draft-07's)
    return schema


# -- order (§6.6.6) and instantActions (§6.9) ------------------------------------------------------


def _action(closed: bool) -> dict[str, Any]:
    parameter = _object({"key": STRING, "value": {"type": ["array", "boolean", "number", "string", "object"]}}, closed=closed)
    return _object(
        {"actionType": STRING, "actionId": STRING, "blockingType": {"enum": list(BLOCKING_TYPES)}},
        {"actionDescription": STRING, "actionParameters": _array(parameter)},
        closed=closed,
    )


def _node_position(closed: bool) -> dict[str, Any]:
    return _object(
        {"x": NUMBER, "y": NUMBER, "mapId": STRING},
        {"theta": {"type": "number", "minimum": -math.pi, "maximum": math.pi}, "allowedDeviationXY": NON_NEGATIVE,
         "allowedDeviationTheta": {"type": "number", "minimum": 0, "maximum": math.pi}, "mapDescription": STRING},
        closed=closed,
    )


def _trajectory(closed: bool) -> dict[str, Any]:
    control_point = _object({"x": NUMBER, "y": NUMBER}, {"weight": NON_NEGATIVE}, closed=closed)
    return _object(
        {"degree": {"type": "number", "minimum": 1}, "knotVector": _array({"type": "number", "minimum": 0, "maximum": 1}),
         "controlPoints": _array(control_point)},
        closed=closed,
    )


def _order(version: str, closed: bool) -> dict[str, Any]:
    node = _object(
        {"nodeId": STRING, "sequenceId": UINT32, "released": BOOLEAN, "actions": _array(_action(closed))},
        {"nodeDescription": STRING, "nodePosition": _node_position(closed)},
        closed=closed,
    )
    edge_optional: dict[str, Any] = {
        "edgeDescription": STRING, "maxSpeed": NUMBER, "maxHeight": NUMBER, "minHeight": NUMBER, "orientation": NUMBER,
        "orientationType": {"enum": ["GLOBAL", "TANGENTIAL"]}, "direction": STRING, "rotationAllowed": BOOLEAN,
        "maxRotationSpeed": NUMBER, "trajectory": _trajectory(closed), "length": NUMBER,
    }
    if version != "2.0":
        edge_optional["corridor"] = _object(
            {"leftWidth": NON_NEGATIVE, "rightWidth": NON_NEGATIVE}, {"corridorRefPoint": {"enum": ["KINEMATICCENTER", "CONTOUR"]}},
            closed=closed,
        )
    edge = _object(
        {"edgeId": STRING, "sequenceId": UINT32, "released": BOOLEAN, "startNodeId": STRING, "endNodeId": STRING,
         "actions": _array(_action(closed))},
        edge_optional,
        closed=closed,
    )
    return _message({"orderId": STRING, "orderUpdateId": UINT32, "nodes": _array(node), "edges": _array(edge)},
                    {"zoneSetId": STRING}, closed=closed)


def _instant_actions(version: str, closed: bool) -> dict[str, Any]:
    return _message({"actions": _array(_action(closed))}, closed=closed)


# -- state (§6.10.6) and visualization (§6.13) -----------------------------------------------------


def _agv_position(closed: bool) -> dict[str, Any]:
    return _object(
        {"positionInitialized": BOOLEAN, "x": NUMBER, "y": NUMBER, "theta": NUMBER, "mapId": STRING},
        {"localizationScore": {"type": "number", "minimum": 0, "maximum": 1}, "deviationRange": NUMBER, "mapDescription": STRING},
        closed=closed,
    )


def _velocity(closed: bool) -> dict[str, Any]:
    return _object({}, {"vx": NUMBER, "vy": NUMBER, "omega": NUMBER}, closed=closed)


def _references(closed: bool) -> dict[str, Any]:
    return _array(_object({"referenceKey": STRING, "referenceValue": STRING}, closed=closed))


def _state(version: str, closed: bool) -> dict[str, Any]:
    node_state = _object({"nodeId": STRING, "sequenceId": UINT32, "released": BOOLEAN},
                         {"nodeDescription": STRING, "nodePosition": _node_position(closed)}, closed=closed)
    edge_state = _object({"edgeId": STRING, "sequenceId": UINT32, "released": BOOLEAN},
                         {"edgeDescription": STRING, "trajectory": _trajectory(closed)}, closed=closed)
    load = _object(
        {},
        {"loadId": STRING, "loadType": STRING, "loadPosition": STRING,
         "boundingBoxReference": _object({"x": NUMBER, "y": NUMBER, "z": NUMBER}, {"theta": NUMBER}, closed=closed),
         "loadDimensions": _object({"length": NUMBER, "width": NUMBER}, {"height": NUMBER}, closed=closed),
         "weight": NON_NEGATIVE},
        closed=closed,
    )
    action_state = _object({"actionId": STRING, "actionStatus": {"enum": list(ACTION_STATUSES)}},
                           {"actionType": STRING, "actionDescription": STRING, "resultDescription": STRING}, closed=closed)
    battery = _object(
        {"batteryCharge": NUMBER, "charging": BOOLEAN},
        {"batteryVoltage": NUMBER, "batteryHealth": {"type": "integer", "minimum": 0, "maximum": 100}, "reach": UINT32},
        closed=closed,
    )
    error_optional: dict[str, Any] = {"errorReferences": _references(closed), "errorDescription": STRING}
    if version != "2.0":
        error_optional["errorHint"] = STRING
    error = _object({"errorType": STRING, "errorLevel": {"enum": list(ERROR_LEVELS)}}, error_optional, closed=closed)
    info = _object({"infoType": STRING, "infoLevel": {"enum": list(INFO_LEVELS)}},
                   {"infoReferences": _references(closed), "infoDescription": STRING}, closed=closed)
    safety = _object({"eStop": {"enum": list(E_STOPS)}, "fieldViolation": BOOLEAN}, closed=closed)
    optional: dict[str, Any] = {
        "zoneSetId": STRING, "agvPosition": _agv_position(closed), "velocity": _velocity(closed), "loads": _array(load),
        "paused": BOOLEAN, "newBaseRequest": BOOLEAN, "distanceSinceLastNode": NUMBER, "information": _array(info),
    }
    if version != "2.0":
        optional["maps"] = _array(_object({"mapId": STRING, "mapVersion": STRING, "mapStatus": {"enum": ["ENABLED", "DISABLED"]}},
                                          {"mapDescription": STRING}, closed=closed))
    required = {
        "orderId": STRING, "orderUpdateId": UINT32, "lastNodeId": STRING, "lastNodeSequenceId": UINT32,
        "nodeStates": _array(node_state), "edgeStates": _array(edge_state), "driving": BOOLEAN,
        "actionStates": _array(action_state), "batteryState": battery, "operatingMode": {"enum": list(OPERATING_MODES)},
        "errors": _array(error), "safetyState": safety,
    }
    return _message(required, optional, closed=closed)


def _visualization(version: str, closed: bool) -> dict[str, Any]:
    return _message({}, {"agvPosition": _agv_position(closed), "velocity": _velocity(closed)}, closed=closed)


def _connection(version: str, closed: bool) -> dict[str, Any]:
    return _message({"connectionState": {"enum": list(CONNECTION_STATES)}}, closed=closed)


# -- factsheet (§6.15) --------------------------------------------------------------------------


def _factsheet(version: str, closed: bool) -> dict[str, Any]:
    type_specification = _object(
        {"seriesName": STRING, "agvKinematic": STRING, "agvClass": STRING, "maxLoadMass": NUMBER,
         "localizationTypes": STRINGS, "navigationTypes": STRINGS},
        {"seriesDescription": STRING},
        closed=closed,
    )
    physical_optional = {"angularSpeedMin": NUMBER, "angularSpeedMax": NUMBER} if version != "2.0" else {}
    physical = _object(
        {"speedMin": NUMBER, "speedMax": NUMBER, "accelerationMax": NUMBER, "decelerationMax": NUMBER,
         "heightMin": NUMBER, "heightMax": NUMBER, "width": NUMBER, "length": NUMBER},
        physical_optional,
        closed=closed,
    )
    string_lengths = _object({}, {key: UINT32 for key in ("msgLen", "topicSerialLen", "topicElemLen", "idLen", "enumLen", "loadIdLen")}
                             | {"idNumericalOnly": BOOLEAN}, closed=closed)
    array_keys = ("order.nodes", "order.edges", "node.actions", "edge.actions", "actions.actionsParameters", "instantActions",
                  "trajectory.knotVector", "trajectory.controlPoints", "state.nodeStates", "state.edgeStates", "state.loads",
                  "state.actionStates", "state.errors", "state.information", "error.errorReferences", "information.infoReferences")
    timing = _object({"minOrderInterval": NUMBER, "minStateInterval": NUMBER},
                     {"defaultStateInterval": NUMBER, "visualizationInterval": NUMBER}, closed=closed)
    limits = _object({"maxStringLens": string_lengths, "maxArrayLens": _object({}, {key: UINT32 for key in array_keys}, closed=closed),
                      "timing": timing}, closed=closed)
    parameter = _object({"key": STRING, "valueDataType": {"enum": ["BOOL", "NUMBER", "INTEGER", "FLOAT", "STRING", "OBJECT", "ARRAY"]}},
                        {"description": STRING, "isOptional": BOOLEAN}, closed=closed)
    agv_action = _object(
        {"actionType": STRING, "actionScopes": _array({"enum": ["INSTANT", "NODE", "EDGE"]})},
        {"actionDescription": STRING, "actionParameters": _array(parameter), "resultDescription": STRING,
         "blockingTypes": _array({"enum": list(BLOCKING_TYPES)})},
        closed=closed,
    )
    optional_parameter = _object({"parameter": STRING, "support": {"enum": ["SUPPORTED", "REQUIRED"]}}, {"description": STRING},
                                 closed=closed)
    features = _object({"optionalParameters": _array(optional_parameter), "agvActions": _array(agv_action)}, closed=closed)
    point = _object({"x": NUMBER, "y": NUMBER}, closed=closed)
    wheel = _object(
        {"type": {"enum": ["DRIVE", "CASTER", "FIXED", "MECANUM"]}, "isActiveDriven": BOOLEAN, "isActiveSteered": BOOLEAN,
         "position": _object({"x": NUMBER, "y": NUMBER}, {"theta": NUMBER}, closed=closed), "diameter": NUMBER, "width": NUMBER},
        {"centerDisplacement": NUMBER, "constraints": STRING},
        closed=closed,
    )
    geometry = _object(
        {},
        {"wheelDefinitions": _array(wheel),
         "envelopes2d": _array(_object({"set": STRING, "polygonPoints": _array(point)}, {"description": STRING}, closed=closed)),
         "envelopes3d": _array(_object({"set": STRING, "format": STRING},
                                       {"data": {"type": "object"}, "url": STRING, "description": STRING}, closed=closed))},
        closed=closed,
    )
    load_set_numbers = ("maxWeight", "minLoadhandlingHeight", "maxLoadhandlingHeight", "minLoadhandlingDepth", "maxLoadhandlingDepth",
                        "minLoadhandlingTilt", "maxLoadhandlingTilt", "agvSpeedLimit", "agvAccelerationLimit", "agvDecelerationLimit",
                        "pickTime", "dropTime")
    load_set = _object(
        {"setName": STRING, "loadType": STRING},
        {"loadPositions": STRINGS, "description": STRING, **{key: NUMBER for key in load_set_numbers},
         "boundingBoxReference": _object({"x": NUMBER, "y": NUMBER, "z": NUMBER}, {"theta": NUMBER}, closed=closed),
         "loadDimensions": _object({"length": NUMBER, "width": NUMBER}, {"height": NUMBER}, closed=closed)},
        closed=closed,
    )
    load_specification = _object({}, {"loadPositions": STRINGS, "loadSets": _array(load_set)}, closed=closed)
    required = {"typeSpecification": type_specification, "physicalParameters": physical, "protocolLimits": limits,
                "protocolFeatures": features, "agvGeometry": geometry, "loadSpecification": load_specification}
    optional: dict[str, Any] = {}
    if version == "2.0":
        required["localizationParameters"] = {"type": "object"}  # named in 2.0's table, its fields never specified
        return _message(required, closed=closed, optional_id_and_time=True)
    network = _object({}, {"dnsServers": STRINGS, "ntpServers": STRINGS, "localIpAddress": STRING, "netmask": STRING,
                           "defaultGateway": STRING}, closed=closed)
    optional["vehicleConfig"] = _object({}, {"versions": _array(_object({"key": STRING, "value": STRING}, closed=closed)),
                                             "network": network}, closed=closed)
    return _message(required, optional, closed=closed)


_BUILDERS = {
    ORDER_KIND: _order, INSTANT_ACTIONS_KIND: _instant_actions, STATE_KIND: _state, CONNECTION_KIND: _connection,
    FACTSHEET_KIND: _factsheet, VISUALIZATION_KIND: _visualization,
}


@functools.cache
def schema(kind: str, version: str, *, closed: bool = True) -> dict[str, Any]:
    """The JSON Schema of one message kind ('order', 'state', …) for protocol version '2.0' or '2.1'."""
    if version not in ("2.0", "2.1"):
        raise ValueError(f"VDA 5050 version {version!r} is not supported (2.0 or 2.1)")
    try:
        builder = _BUILDERS[kind]
    except KeyError:
        raise ValueError(f"no VDA 5050 message {kind!r}; known: {', '.join(KINDS)}") from None
    result = builder(version, closed)
    result["title"] = f"VDA 5050 {version} {kind}"
    return result
