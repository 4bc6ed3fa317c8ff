"""The master control against vehicles nobody here wrote: vda-5050-lib 1.4.0's virtual vehicles (VDA 5050 2.0) on mosquitto."""

from __future__ import annotations

from pathlib import Path

import pytest
from vda5050_support import LibVehicles, Wire, adapter, start_plant, vehicle_yaml, wait_for, write_plant

P1, P3, T01_SRC, T02_SRC, U2 = (7.925, 5.925), (7.925, 2.925), (3.5, 7.5), (18.5, 7.5), (5.5, 6.6)


@pytest.fixture(autouse=True)
def vda_5050_lib() -> None:
    LibVehicles.require()


def lib_vehicle(serial: str, x: float, y: float, node: str) -> dict:
    return {"manufacturer": "acme", "serialNumber": serial, "x": x, "y": y, "lastNodeId": node}


def lib_robot(robot_id: str, serial: str, x: float, y: float) -> str:
    return vehicle_yaml(robot_id, serial, x, y, manufacturer="acme", key="instantActions", speed=1.0)


def goal(db, robot: str, point: tuple[float, float], currloc: int = 0) -> None:
    assert db.submit([(f"{robot}_xgoal", point[0]), (f"{robot}_ygoal", point[1]), (f"{robot}_status", True),
                      (f"{robot}_currloc", currloc)], "test") == [None] * 4


async def test_order_update_pause_and_cancel_with_vda_5050_lib(tmp_path: Path, mosquitto) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [lib_robot("r01", "v1", *P1)])
    runtime = await start_plant(tagdb)
    db = runtime.db
    try:
        async with Wire(mosquitto.port, "2.0") as wire, LibVehicles(mosquitto.port, [lib_vehicle("v1", *P1, "p1")], speed=1.0):
            await wait_for(lambda: db.value("r01_online"), 10, "the vehicle reports")
            master = adapter(runtime, "vda5050")
            await wait_for(lambda: master.links["r01"].factsheet is not None, 10, "its factsheet, asked for with factsheetRequest")
            assert master.factsheet_differences["r01"] == ["max_linear_speed: robots.yaml 1, factsheet speedMax 1"] or \
                master.factsheet_differences["r01"] == []
            goal(db, "r01", T02_SRC)  # far: p1 u3 u4 ... u8 t02_src, released two nodes at a time
            await wait_for(lambda: db.value("r01_navstate") == "moving", 10, "the order acknowledged")
            await wait_for(lambda: master.links["r01"].trip is not None and master.links["r01"].trip.update_id >= 2, 20,
                           "the base grown by order updates the library stitched")
            # Pause: the vehicle stands, the order stays.
            await runtime.commands.call("vda5050.instant_action", {"robot": "r01", "action": "startPause"}, _engineer())
            await wait_for(lambda: db.value("_sys.vda5050.r01.paused"), 10, "paused")
            x = db.value("r01_xpos")
            await wait_for(lambda: master.links["r01"].state is not None and not master.links["r01"].state.driving, 5, "standing")
            await runtime.commands.call("vda5050.instant_action", {"robot": "r01", "action": "stopPause"}, _engineer())
            await wait_for(lambda: not db.value("_sys.vda5050.r01.paused") and db.value("r01_xpos") != x, 10, "driving on")
            # A new goal while driving: an update stitched at the decision point (same orderId), not a cancel.
            order_id = master.links["r01"].trip.order_id
            goal(db, "r01", U2)
            await wait_for(lambda: db.value("r01_navstate") == "arrived", 30, "arrived at the new goal")
            assert all(message["orderId"] == order_id for message in wire.orders("v1"))
            assert abs(db.value("r01_xpos") - U2[0]) < 0.5
            # Cancel: the library reports cancelOrder RUNNING then FINISHED; the robot is idle, no alarm.
            goal(db, "r01", T01_SRC)
            await wait_for(lambda: db.value("r01_navstate") == "moving", 10, "moving again")
            await runtime.commands.call("vda5050.instant_action", {"robot": "r01", "action": "cancelOrder"}, _engineer())
            await wait_for(lambda: master.links["r01"].state is not None and not master.links["r01"].state.node_states
                           and not master.links["r01"].state.driving, 10, "the vehicle cancelled and stands")
            assert db.value("r01_navstate") == "idle" and not db.value("r01_status")
            instant = [message for _, topic, message in wire.messages if topic.endswith("/instantActions")]
            assert [m["actions"][0]["actionType"] for m in instant] == ["factsheetRequest", "startPause", "stopPause", "cancelOrder"]
            assert wire.violations == [] and master.schema_violations == 0
            assert db.value("_sys.vda5050.r01.error") == "" and db.value("_sys.vda5050.r01.rejected") == ""
    finally:
        await runtime.stop()


def _engineer():
    from softplc.core.origin import Origin
    from softplc.core.roles import Role

    return Origin("test", "erna", role=Role.ENGINEER)
