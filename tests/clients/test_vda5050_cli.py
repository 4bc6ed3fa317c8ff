"""`softplc vda5050 vehicles|factsheets|orders|action` against a running plant over OPC UA: by role, audited."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from softplc.app.cli import main
from softplc.clients.robot_agent.vda5050.agent import VehicleAgent
from softplc.core.clock import RealClock
from softplc.core.origin import Origin
from softplc.core.roles import Role
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import load_robots
from tests.opcua_support import PASSWORDS
from tests.vda5050_support import MAP, adapter, start_plant, vehicle_yaml, wait_for, write_plant


async def softplc(capsys, monkeypatch, endpoint: str, *argv: str, user: str | None = None) -> tuple[int, str, str]:
    """Run the command line in a thread (it has its own event loop) beside the running plant."""
    if user is not None:
        monkeypatch.setenv("SOFTPLC_PASSWORD", PASSWORDS[user])
        argv = (*argv, "--user", user)
    code = await asyncio.to_thread(main, [*argv, "--endpoint", endpoint])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


async def test_list_the_vehicles_and_send_an_instant_action_as_an_engineer(tmp_path: Path, mosquitto, capsys, monkeypatch) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [vehicle_yaml("r01", "tb1", 7.925, 5.925)])
    runtime = await start_plant(tagdb, opcua=True)
    robots = load_robots(tagdb.parent / "robots.yaml")
    vehicle = VehicleAgent(robots["r01"], Floor(load_map(MAP)), MqttSettings(port=mosquitto.port, client_id="cli"), clock=RealClock(),
                           state_interval=0.5)
    driving = asyncio.ensure_future(vehicle.run())
    endpoint = adapter(runtime, "opcua").endpoint
    try:
        await wait_for(lambda: runtime.db.value("r01_online"), 10, "r01 reports")
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "vda5050", "vehicles")
        assert code == 0, err
        assert out.splitlines()[0].split()[:4] == ["robot", "vehicle", "alive", "connection"]
        assert "softplc/tb1" in out and "ONLINE" in out
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "vda5050", "factsheets", "--format", "json")
        assert code == 0 and json.loads(out)[0]["factsheet"]["length_mm"] == 255
        code, _, err = await softplc(capsys, monkeypatch, endpoint, "vda5050", "action", "r01", "startPause", user="operator")
        assert code == 4 and "vda5050.instant_action needs the engineer role, and user 'operator' does not have it" in err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "vda5050", "action", "r01", "startPause", user="engineer")
        assert code == 0 and out.startswith("sent startPause to r01 (actionId r01.startPause."), err
        await wait_for(lambda: runtime.db.value("_sys.vda5050.r01.paused"), 10, "the vehicle paused")
        code, _, err = await softplc(capsys, monkeypatch, endpoint, "vda5050", "action", "r9", "stopPause", user="engineer")
        assert code == 1 and "no VDA 5050 vehicle 'r9'; vehicles: r01" in err
        trail = await runtime.commands.call("audit.query", {"kind": "command"}, Origin("test", role=Role.ENGINEER))
        calls = [(row["user"], row["accepted"], row["arguments"].get("action")) for row in trail if row["name"] == "vda5050.instant_action"]
        assert ("operator", False, "startPause") in calls and ("engineer", True, "startPause") in calls
    finally:
        driving.cancel()
        await asyncio.gather(driving, return_exceptions=True)
        await runtime.stop()
