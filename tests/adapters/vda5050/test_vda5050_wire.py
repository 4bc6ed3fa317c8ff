"""Bad input from the wire: each kind of malformed vehicle message is refused with a located reason, shown as the vehicle's
error (an alarm), logged a few times at most — and the pose in the tags never moves on it."""

from __future__ import annotations

import asyncio
import json
import logging
from pathlib import Path

import pytest
from vda5050_support import adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.clients.robot_agent.vda5050.vehicle import Vehicle
from softplc.core.clock import RealClock
from softplc.core.origin import Origin
from softplc.protocols.mqtt import MqttConnection
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.protocols.vda5050.messages import Headers
from softplc.robotics.robots import Pose

TOPIC = "uagv/v2/softplc/tb1/state"


def state(x: float, y: float, **changes) -> dict:
    vehicle = Vehicle("2.0")
    vehicle.last_node_id = "p1"
    body = vehicle.state(Pose(x, y), 0.0, 0.0)
    return {**Headers("2.0", "softplc", "tb1").next("state", 1_767_225_600.0), **body, **changes}


@pytest.mark.parametrize(("payload", "reason"), [
    (b"{\"headerId\": 1, ", "not JSON"),
    (json.dumps(state(9.0, 9.0, driving="yes")).encode(), "driving: 'yes' is not of type 'boolean'"),
    (json.dumps({k: v for k, v in state(9.0, 9.0).items() if k != "agvPosition" and k != "errors"}).encode(), "'errors' is a required property"),
    (json.dumps({**state(9.0, 9.0), "agvPosition": {**state(9.0, 9.0)["agvPosition"], "x": "9"}}).encode(), "agvPosition.x"),
    (json.dumps(state(9.0, 9.0, serialNumber="tb2")).encode(), "says it is from softplc/tb2"),
    (b"x" * (10 * 1024 * 1024), "10485760 bytes"),
    (json.dumps({**state(9.0, 9.0), "agvPosition": {**state(9.0, 9.0)["agvPosition"], "mapId": "other"}}).encode(), "on map 'other'"),
])
async def test_a_bad_state_is_refused_shown_and_the_pose_stays(tmp_path: Path, mosquitto, payload: bytes, reason: str, caplog) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [vehicle_yaml("r01", "tb1", 7.925, 5.925)])
    runtime = await start_plant(tagdb)
    db = runtime.db
    sender = MqttConnection(MqttSettings(port=mosquitto.port, client_id="fake"), "vehicle", RealClock())
    task = asyncio.ensure_future(sender.run())
    try:
        await wait_for(lambda: sender.connected and db.value("_sys.vda5050.broker"), 10, "both connected")
        await sender.publish(TOPIC, json.dumps(state(7.925, 5.925)))
        await wait_for(lambda: db.value("r01_online"), 10, "a good state")
        caplog.set_level(logging.WARNING, logger="softplc.adapters.vda5050")
        for _ in range(20 if len(payload) < 1_000_000 else 2):  # a flood of the same mistake
            await sender.publish(TOPIC, payload)
        await wait_for(lambda: reason in db.value("_sys.vda5050.r01.error"), 10, f"the error names {reason!r}")
        assert (db.value("r01_xpos"), db.value("r01_ypos")) == (7.925, 5.925)  # never the bad message's pose
        master = adapter(runtime, "vda5050")
        await wait_for(lambda: master.bad_messages >= (20 if len(payload) < 1_000_000 else 2), 10, "every one counted")
        lines = [record for record in caplog.records if "bad state message" in record.getMessage()]
        assert 1 <= len(lines) <= 2, [record.getMessage() for record in lines]  # rate-limited: one line, then a summary later
        for _ in range(50):  # the alarms are evaluated at the next scan boundary
            alarms = await runtime.commands.call("alarms.list", {"state": "all"}, Origin("test"))
            found = next(item for item in alarms if item["name"] == "r01_vehicle_error")
            if found["active"]:
                break
            await asyncio.sleep(0.05)
        assert found["active"] and reason in found["message"]
        await sender.publish(TOPIC, json.dumps(state(7.0, 5.9)))  # the next good state is believed again
        await wait_for(lambda: db.value("r01_xpos") == 7.0 and db.value("_sys.vda5050.r01.error") == "", 10, "a good state again")
    finally:
        task.cancel()
        await sender.close()
        await runtime.stop()


async def test_unknown_vehicles_and_orders_nobody_sent_are_logged_not_believed(tmp_path: Path, mosquitto, caplog) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [vehicle_yaml("r01", "tb1", 7.925, 5.925)])
    runtime = await start_plant(tagdb)
    db = runtime.db
    sender = MqttConnection(MqttSettings(port=mosquitto.port, client_id="fake"), "vehicle", RealClock())
    task = asyncio.ensure_future(sender.run())
    caplog.set_level(logging.WARNING, logger="softplc.adapters.vda5050")
    try:
        await wait_for(lambda: sender.connected and db.value("_sys.vda5050.broker"), 10, "both connected")
        stranger = {**state(1.0, 1.0), "serialNumber": "zz9"}
        for _ in range(30):
            await sender.publish("uagv/v2/softplc/zz9/state", json.dumps(stranger))
        await sender.publish(TOPIC, json.dumps(state(7.925, 5.925, orderId="theirs", nodeStates=[
            {"nodeId": "u3", "sequenceId": 2, "released": True}])))
        await wait_for(lambda: db.value("r01_online"), 10, "r01's state")
        await wait_for(lambda: any("never sent" in r.getMessage() for r in caplog.records), 10, "the foreign order noticed")
        unknown = [r for r in caplog.records if "no driver: vda5050 robot" in r.getMessage()]
        assert len(unknown) == 1  # thirty messages, one line (and a summary after ten seconds)
        # A goal while the vehicle is busy with an order this master never gave: cancelled once, then ours.
        received: list[dict] = []
        sender.subscribe("uagv/v2/softplc/tb1/instantActions", lambda t, p, r: received.append(json.loads(p)))
        await asyncio.sleep(0.2)  # the subscription reaches the broker
        db.submit([("r01_xgoal", 3.5), ("r01_ygoal", 7.5), ("r01_status", True)], "test")
        await wait_for(lambda: any(a["actionType"] == "cancelOrder" for m in received for a in m["actions"]), 10, "the foreign order cancelled")
    finally:
        task.cancel()
        await sender.close()
        await runtime.stop()
