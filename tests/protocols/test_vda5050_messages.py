"""VDA 5050 messages (softplc/protocols/vda5050): schemas from the spec's tables, order rules, bad input, our vehicle's logic."""

from __future__ import annotations

import json

import pytest

from softplc.clients.robot_agent.vda5050.factsheet import factsheet_of
from softplc.clients.robot_agent.vda5050.vehicle import Vehicle
from softplc.protocols.vda5050 import topics
from softplc.protocols.vda5050.messages import (
    FactsheetSummary,
    Headers,
    VehicleState,
    action,
    edge,
    instant_actions_of,
    node,
)
from softplc.protocols.vda5050.validation import MessageError, decode, problems
from softplc.robotics.robots import Pose, parse_robots

ROBOTS = """
robots:
  - id: r04
    name: TurtleBot 4
    driver: vda5050
    vda5050: {manufacturer: softplc, serial_number: tb4}
    length_mm: 255
    width_mm: 255
    height_mm: 400
    load_capacity: 20
    max_linear_speed: 0.2
    max_angular_speed: 0.4
    start: {x: 1.0, y: 1.0}
"""


def header(version: str, kind: str) -> dict:
    return Headers(version, "softplc", "tb4").next(kind, 1_767_225_600.0)


def order(version: str, released: int = 3, **changes) -> dict:
    names = ["a", "b", "c"]
    nodes = [node(name, 2 * i, i < released, float(i), 0.0, "factory", deviation=0.3) for i, name in enumerate(names)]
    edges = [edge(f"{names[i]}-{names[i + 1]}", 2 * i + 1, i + 1 < released, names[i], names[i + 1]) for i in range(2)]
    nodes[-1]["actions"] = [action("pick", "p1", "HARD", {"stationType": "floor", "loadType": "EPAL"})]
    return {**header(version, "order"), "orderId": "o1", "orderUpdateId": 0, "nodes": nodes, "edges": edges, **changes}


@pytest.mark.parametrize("version", ["2.0", "2.1"])
def test_what_our_master_and_vehicle_send_is_valid_for_the_closed_schemas(version: str) -> None:
    assert problems("order", version, order(version)) == []
    assert problems("order", version, order(version, released=1)) == []  # base + horizon
    actions = {**header(version, "instantActions"), "actions": [action("cancelOrder", "c1", "HARD")]}
    assert problems("instantActions", version, actions) == []
    spec = parse_robots(ROBOTS)["r04"]
    factsheet = {**header(version, "factsheet"), **factsheet_of(spec, version, 1.0)}
    assert problems("factsheet", version, factsheet) == []
    vehicle = Vehicle(version)
    vehicle.pose = Pose(0.0, 0.0)
    vehicle.on_order(json.dumps(order(version)).encode())
    state = {**header(version, "state"), **vehicle.state(Pose(0.0, 0.0), 0.0, 0.0)}
    assert problems("state", version, state) == []
    assert problems("connection", version, {**header(version, "connection"), "connectionState": "CONNECTIONBROKEN"}) == []
    summary = FactsheetSummary.from_message(factsheet)
    assert (summary.length_mm, summary.max_linear_speed, summary.max_load_mass) == (255.0, 0.2, 20)


def test_the_versions_differ_where_the_spec_does() -> None:
    with_corridor = order("2.1")
    with_corridor["edges"][0]["corridor"] = {"leftWidth": 0.5, "rightWidth": 0.5}
    assert problems("order", "2.1", with_corridor) == []
    assert any("corridor" in problem for problem in problems("order", "2.0", with_corridor))  # 2.0 has no corridors
    error = {"errorType": "x", "errorLevel": "WARNING", "errorHint": "h"}
    state = {**header("2.1", "state"), **Vehicle("2.1").state(None, 0, 0)}
    assert problems("state", "2.1", {**state, "errors": [error]}) == []
    assert problems("state", "2.0", {**state, "errors": [error]})  # errorHint and maps came with 2.1


def test_order_graph_rules_a_schema_cannot_say() -> None:
    bad = order("2.0")
    bad["nodes"][1]["sequenceId"] = 3
    assert any("odd" in problem for problem in problems("order", "2.0", bad))
    bad = order("2.0", released=1)
    bad["nodes"][2]["released"] = True
    assert any("base must come before the horizon" in problem for problem in problems("order", "2.0", bad))
    bad = order("2.0")
    bad["edges"].pop()
    assert problems("order", "2.0", bad) == ["edges: 1 edges for 3 nodes (must be one fewer)"]


@pytest.mark.parametrize(("payload", "expected"), [
    (b"{not json", "not JSON"),
    (b"\xff\xfe", "not UTF-8"),
    (b"[1, 2]", "must be a JSON object"),
    (b'{"headerId": NaN}', "NaN"),
])
def test_bad_payloads_are_refused_with_a_reason(payload: bytes, expected: str) -> None:
    with pytest.raises(MessageError, match=expected):
        decode(payload, "state", "2.0")


def test_a_wrong_type_and_a_missing_field_are_located() -> None:
    state = {**header("2.0", "state"), **Vehicle("2.0").state(Pose(1, 2), 0, 0)}
    state["agvPosition"]["x"] = "far away"
    del state["batteryState"]
    with pytest.raises(MessageError) as caught:
        decode(json.dumps(state), "state", "2.0")
    assert "agvPosition.x: 'far away' is not of type 'number'" in str(caught.value)
    assert "'batteryState' is a required property" in str(caught.value)
    decoded = VehicleState.from_message(decode(json.dumps({**state, "agvPosition": {**state["agvPosition"], "x": 3},
                                                           "batteryState": {"batteryCharge": 80, "charging": False}}), "state", "2.0"))
    assert decoded.position == (3.0, 2.0, 0.0) and decoded.battery_charge == 80


def test_the_instant_actions_key_of_vda_5050_lib_is_understood() -> None:
    assert instant_actions_of({"instantActions": [{"actionId": "a"}]}) == [{"actionId": "a"}]
    assert instant_actions_of({"actions": [{"actionId": "b"}]}) == [{"actionId": "b"}]
    vehicle = Vehicle("2.0")
    vehicle.on_instant_actions(json.dumps({**header("2.0", "instantActions"),
                                           "instantActions": [action("startPause", "s1", "HARD")]}).encode())
    assert vehicle.paused and vehicle.actions["s1"].status == "FINISHED"


def test_topics() -> None:
    assert topics.topic("uagv", "2.1", "acme", "001", topics.ORDER) == "uagv/v2/acme/001/order"
    assert topics.parse("uagv/v2/acme/001/state", "uagv", "2.0") == topics.VehicleTopic("acme", "001", "state")
    assert topics.parse("uagv/v1/acme/001/state", "uagv", "2.0") is None


def test_our_vehicle_accepts_stitches_ignores_and_rejects_as_figure_8_says() -> None:
    vehicle = Vehicle("2.0")
    vehicle.pose = Pose(5.0, 5.0)
    vehicle.on_order(json.dumps(order("2.0", released=1)).encode())
    assert vehicle.errors[0]["errorType"] == "noRouteError" and not vehicle.nodes  # the start node is far away
    vehicle.pose = Pose(0.0, 0.0)
    first = order("2.0", released=1)
    vehicle.on_order(json.dumps(first).encode())
    assert vehicle.errors == [] and [w.node_id for w in vehicle.nodes] == ["a", "b", "c"]
    vehicle.step(0.0, Pose(0.0, 0.0), False)
    assert vehicle.last_node_id == "a" and vehicle.target(Pose(0, 0)) is None  # "a" is the decision point: wait
    update = order("2.0", released=3, orderUpdateId=1)
    update["nodes"], update["edges"] = update["nodes"], update["edges"]
    vehicle.on_order(json.dumps(update).encode())
    assert vehicle.errors == [] and vehicle.order_update_id == 1 and vehicle.target(Pose(0, 0)) == (1.0, 0.0)
    vehicle.on_order(json.dumps(update).encode())  # identical resend: ignored
    assert vehicle.errors == [] and vehicle.order_update_id == 1
    vehicle.on_order(json.dumps(order("2.0", orderUpdateId=0)).encode())
    assert vehicle.errors[-1]["errorType"] == "orderUpdateError"
    vehicle.step(1.0, Pose(1.0, 0.0), False)
    vehicle.step(2.0, Pose(2.0, 0.0), False)
    assert vehicle.actions["p1"].status == "RUNNING" and vehicle.target(Pose(2, 0)) is None
    vehicle.step(5.0, Pose(2.0, 0.0), False)
    assert vehicle.actions["p1"].status == "FINISHED" and len(vehicle.loads) == 1
