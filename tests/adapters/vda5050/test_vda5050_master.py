"""The master control drives our own simulated TurtleBots as VDA 5050 vehicles through a real mosquitto."""

from __future__ import annotations

import asyncio
import functools
from pathlib import Path

from softplc.clients.robot_agent.vda5050.agent import VehicleAgent
from softplc.core.clock import RealClock
from softplc.core.tags import Quality
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.robotics.controller import SpeedLimits
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import load_robots

from vda5050_support import MAP, Wire, adapter, start_plant, vehicle_yaml, wait_for, write_plant

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
