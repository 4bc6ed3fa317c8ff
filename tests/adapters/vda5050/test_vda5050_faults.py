"""Faults, as users of other masters asked (issue 24): rejections as alarms, lost and killed vehicles, a broker restart."""

from __future__ import annotations

import asyncio
import os
import signal
import time
from pathlib import Path

import pytest
from vda5050_support import ROADMAP, LibVehicles, adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.core.origin import Origin
from softplc.core.tags import Quality

P1, P3, T01_SRC, T02_SRC = (7.925, 5.925), (7.925, 2.925), (3.5, 7.5), (18.5, 7.5)


@pytest.fixture(autouse=True)
def vda_5050_lib() -> None:
    LibVehicles.require()


def lib_vehicle(serial: str, x: float, y: float, node: str) -> dict:
    return {"manufacturer": "acme", "serialNumber": serial, "x": x, "y": y, "lastNodeId": node}


def lib_robot(robot_id: str, serial: str, x: float, y: float) -> str:
    return vehicle_yaml(robot_id, serial, x, y, manufacturer="acme", key="instantActions", speed=1.0)


def goal(db, robot: str, point: tuple[float, float], currloc: int = 0, task: int = 0) -> None:
    assert db.submit([(f"{robot}_xgoal", point[0]), (f"{robot}_ygoal", point[1]), (f"{robot}_status", True),
                      (f"{robot}_currloc", currloc), (f"{robot}_tcurr", task)], "test") == [None] * 5


async def alarm(runtime, name: str) -> dict:
    alarms = await runtime.commands.call("alarms.list", {"state": "all"}, Origin("test"))
    return next(item for item in alarms if item["name"] == name)


async def test_a_rejected_order_is_an_alarm_with_the_vehicles_own_words(tmp_path: Path, mosquitto) -> None:
    # The roadmap asks for a load type the virtual vehicle cannot pick (it takes EPAL only): it rejects the order.
    roadmap = tmp_path / "roadmap.yaml"
    roadmap.write_text(ROADMAP.read_text().replace("loadType: EPAL", "loadType: XLT1200"))
    tagdb = write_plant(tmp_path, mosquitto.url, [lib_robot("r01", "v1", *P1)])
    tagdb.write_text(tagdb.read_text().replace(str(ROADMAP), str(roadmap)))
    runtime = await start_plant(tagdb)
    db = runtime.db
    try:
        async with LibVehicles(mosquitto.port, [lib_vehicle("v1", *P1, "p1")], speed=1.0):
            await wait_for(lambda: db.value("r01_online"), 10, "the vehicle reports")
            goal(db, "r01", T01_SRC, currloc=1, task=1)  # on the way to a source: a pick at the station
            await wait_for(lambda: db.value("r01_navstate") == "failed", 10, "the order refused")
            text = db.value("_sys.vda5050.r01.rejected")
            assert "not executable" in text and not db.value("r01_status")
            assert db.value("r01_navreason") == text[:300]
            found = None
            for _ in range(100):
                found = await alarm(runtime, "r01_order_rejected")
                if found["active"]:
                    break
                await asyncio.sleep(0.05)
            assert found["active"] and "not executable" in found["message"], found
            assert adapter(runtime, "vda5050").links["r01"].trip is None  # no resend of a refused order
    finally:
        await runtime.stop()


async def test_a_vehicle_killed_mid_order_gives_its_task_back_and_a_frozen_one_is_flagged_from_its_states(tmp_path: Path, mosquitto) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [lib_robot("r01", "v1", *P1), lib_robot("r02", "v2", *P3)], lost_after="2s")
    runtime = await start_plant(tagdb)
    db = runtime.db
    try:
        async with LibVehicles(mosquitto.port, [lib_vehicle("v1", *P1, "p1")], speed=0.5) as first, \
                LibVehicles(mosquitto.port, [lib_vehicle("v2", *P3, "p3")], speed=0.5, heartbeat=30) as second:
            await wait_for(lambda: db.value("r01_online") and db.value("r02_online"), 10, "both report")
            goal(db, "r01", T02_SRC, currloc=1, task=2)
            await wait_for(lambda: db.value("r01_navstate") == "moving" and db.value("r01_speed") > 0, 10, "r01 on its way")
            first.kill()  # a crash: the broker publishes its last will, CONNECTIONBROKEN
            await wait_for(lambda: not db.value("r01_online"), 5, "r01 flagged lost")
            assert db.value("r01_navstate") == "offline" and db["r01_xpos"].quality is Quality.BAD
            assert (db.value("r01_currloc"), db.value("r01_tcurr"), db.value("r01_status")) == (0, 0, False)  # task 2 is free again
            assert db.value("_sys.vda5050.r01.connection") == "CONNECTIONBROKEN"
            # A frozen vehicle keeps its MQTT session (heartbeat 30 s: no will for 45 s); its states stop: lost after 2 s.
            os.kill(second.process.pid, signal.SIGSTOP)
            frozen = time.monotonic()
            try:
                await wait_for(lambda: not db.value("r02_online"), 10, "r02 flagged lost from its missing states")
                flagged = time.monotonic() - frozen
                assert flagged < 4.0, f"flagged after {flagged:.1f} s, its state interval is 1 s"
                assert db.value("_sys.vda5050.r02.connection") == "ONLINE"  # the connection topic alone would say all is well
            finally:
                os.kill(second.process.pid, signal.SIGCONT)
            await wait_for(lambda: db.value("r02_online") and db["r02_xpos"].quality is Quality.GOOD, 5, "r02 back on its next state")
            assert db.value("r02_navstate") == "idle"  # not 'offline' any more: the motion sequencer gives it trips again
    finally:
        await runtime.stop()


async def test_a_broker_restart_marks_the_fleet_bad_and_the_master_subscribes_again(tmp_path: Path, mosquitto) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [lib_robot("r01", "v1", *P1)], lost_after="2s")
    runtime = await start_plant(tagdb)
    db = runtime.db
    try:
        async with LibVehicles(mosquitto.port, [lib_vehicle("v1", *P1, "p1")], speed=1.0):
            await wait_for(lambda: db.value("r01_online"), 10, "the vehicle reports")
            mosquitto.stop()
            await wait_for(lambda: not db.value("_sys.vda5050.broker"), 10, "the broker missed")
            assert not db.value("r01_online") and db["r01_xpos"].quality is Quality.BAD
            for _ in range(100):  # the alarm has a 3 s on-delay: a broker that blinks is no alarm
                if (await alarm(runtime, "vda5050_broker_down"))["active"]:
                    break
                await asyncio.sleep(0.1)
            assert (await alarm(runtime, "vda5050_broker_down"))["active"]
            mosquitto.start()
            back = await wait_for(lambda: db.value("_sys.vda5050.broker") and db.value("r01_online"), 15,
                                  "the master and the vehicle back, subscribed again")
            assert db["r01_xpos"].quality is Quality.GOOD
            assert not (await alarm(runtime, "vda5050_broker_down"))["active"]
            goal(db, "r01", T01_SRC)
            await wait_for(lambda: db.value("r01_navstate") == "arrived", 30, "an order after the restart")
            assert back < 15
    finally:
        await runtime.stop()
