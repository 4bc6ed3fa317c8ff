"""The master control drives our own simulated TurtleBots as VDA 5050 vehicles through a real mosquitto."""

from __future__ import annotations

import asyncio
import functools
import json
from pathlib import Path

from vda5050_support import MAP, Wire, adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.clients.robot_agent.vda5050.agent import VehicleAgent
from softplc.core.clock import RealClock
from softplc.core.tags import Quality
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.robotics.controller import SpeedLimits
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import load_robots

P1, P3, T01_SRC, U3 = (7.925, 5.925), (7.925, 2.925), (3.5, 7.5), (7.925, 6.6)


@functools.cache
def factory_floor() -> Floor:
    return Floor(load_map(MAP))


def agents(tagdb: Path, port: int, version: str, *ids: str) -> list[VehicleAgent]:
    robots = load_robots(tagdb.parent / "robots.yaml")
    floor = factory_floor()
    settings = MqttSettings(port=port, client_id="test", keepalive=2)
    return [VehicleAgent(robots[robot_id], floor, settings, version=version, clock=RealClock(), state_interval=0.5,
                         limits=SpeedLimits(1.0, 3.0, 2.0, 6.0)) for robot_id in ids]


async def test_a_goal_becomes_an_order_the_vehicle_drives_and_every_message_fits_the_schema(tmp_path: Path, mosquitto) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [vehicle_yaml("r01", "tb1", *P1), vehicle_yaml("r02", "tb2", *P3)], version="2.1")
    runtime = await start_plant(tagdb)
    db = runtime.db
    vehicles = agents(tagdb, mosquitto.port, "2.1", "r01", "r02")
    tasks = [asyncio.ensure_future(vehicle.run()) for vehicle in vehicles]
    try:
        async with Wire(mosquitto.port, "2.1") as wire:
            await wait_for(lambda: db.value("r01_online") and db.value("r02_online"), 10, "both vehicles report")
            assert db["r01_xpos"].quality is Quality.GOOD and abs(db.value("r01_xpos") - P1[0]) < 0.01
            assert db.value("_sys.vda5050.broker") is True
            # A goal written like the motion sequencer writes it: the station's coordinates and status busy, currloc 1 (to source).
            db.submit([("r01_xgoal", T01_SRC[0]), ("r01_ygoal", T01_SRC[1]), ("r01_status", True), ("r01_currloc", 1)], "test")
            await wait_for(lambda: db.value("r01_navstate") == "moving", 10, "r01 acknowledged its order and drives")
            order = wire.orders("tb1")[0]
            assert [n["nodeId"] for n in order["nodes"]] == ["p1", "u3", "u2", "u1", "t01_src"]
            assert [n["released"] for n in order["nodes"]] == [True, True, True, False, False]  # lookahead 2: base + horizon
            assert order["nodes"][-1]["actions"][0]["actionType"] == "pick"
            assert db.value("_sys.vda5050.r01.base") == "p1 u3 u2" and db.value("_sys.vda5050.r01.horizon") == "u1 t01_src"
            await wait_for(lambda: db.value("r01_navstate") == "arrived" and not db.value("r01_status"), 40, "r01 arrived and picked")
            assert abs(db.value("r01_xpos") - T01_SRC[0]) < 0.5 and abs(db.value("r01_ypos") - T01_SRC[1]) < 0.5
            updates = [message["orderUpdateId"] for message in wire.orders("tb1")]
            assert updates == sorted(updates) and updates[-1] >= 1  # the base grew by stitched updates
            assert vehicles[0].vehicle.loads  # the pick ran on the vehicle
            assert wire.violations == [] and adapter(runtime, "vda5050").schema_violations == 0
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await runtime.stop()


async def test_our_vehicle_drives_through_every_node_of_its_base_at_the_turtlebots_own_speed(tmp_path: Path) -> None:
    """On the simulated clock, no broker: the agent's TurtleBot (0.2 m/s) passes each node within its deviation and
    runs its pick; it once stopped 0.4 m short of the first node, its driver restarting the trip at every cycle."""
    from softplc.clients.robot_agent.vda5050.agent import VehicleIO
    from softplc.core.clock import SimClock
    from softplc.protocols.vda5050.messages import Headers, action, edge, node
    from softplc.robotics.loop import ControlLoop

    tagdb = write_plant(tmp_path, "mqtt://127.0.0.1:1", [vehicle_yaml("r01", "tb1", 10.0, 7.6, speed=0.2)])
    clock = SimClock()
    vehicle = VehicleAgent(load_robots(tagdb.parent / "robots.yaml")["r01"], factory_floor(), MqttSettings(port=1), clock=clock)
    route = [("q1", 10.0, 7.6), ("u4", 10.0, 6.6), ("u5", 12.5, 6.6)]
    nodes = [node(name, 2 * i, True, x, y, "factory", deviation=0.3) for i, (name, x, y) in enumerate(route)]
    nodes[-1]["actions"] = [action("pick", "p1", "HARD")]
    edges = [edge(f"{route[i][0]}-{route[i + 1][0]}", 2 * i + 1, True, route[i][0], route[i + 1][0]) for i in range(2)]
    order = {**Headers("2.0", "softplc", "tb1").next("order", 0.0), "orderId": "o1", "orderUpdateId": 0, "nodes": nodes, "edges": edges}
    vehicle.vehicle.on_order(json.dumps(order).encode())  # straight in: no broker here (states are not sent)
    loop = asyncio.ensure_future(ControlLoop(vehicle.driver, VehicleIO(vehicle), clock, 0.1).run())
    try:
        await clock.drive(until=60.0)
    finally:
        loop.cancel()
    assert vehicle.vehicle.last_node_id == "u5" and vehicle.vehicle.nodes == []
    assert vehicle.vehicle.actions["p1"].status == "FINISHED"
