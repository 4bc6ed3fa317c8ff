"""A limit alarm that returns to normal keeps its priority (ISA-18.2), and its message takes the values at the clear.

Issue 21, item 12: an alarm with levels (hi high, hihi critical, the alarm itself medium by
default) showed Critical while active and Medium once returned unacknowledged — in the summary,
the journal and the OPC UA event's Severity — and its cleared row kept the message of the
activation ("level at 97 m" beside the value 50). Checked on the simulated clock, through the
commands (summary, list, journal), the events, and an asyncua client subscribed to the events.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

from asyncua import Client, ua

from softplc.adapters.opcua import OpcUaServer, OpcUaSettings
from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from tests.alarms_support import DRIVER, call, plant, simulate, write
from tests.opcua_support import PASSWORDS, add_users

LEVELS = """
definitions:
  - {name: level_hi, limit: {tag: level, hi: {limit: 90, priority: high}, hihi: {limit: 95, priority: critical}},
     message: "level at {value:.0f} m ({level} {limit:g})"}
"""


async def test_a_cleared_limit_alarm_keeps_its_priority_and_says_the_value_at_the_clear(tmp_path: Path) -> None:
    steps = [
        write(1.05, "level", 97), call(1.5, "alarms.summary", role="viewer"),
        write(2.05, "level", 50), call(2.5, "alarms.summary", role="viewer"), call(2.5, "alarms.list", role="viewer", state="unacknowledged"),
        call(3.05, "alarms.acknowledge", alarm="level_hi"),
        call(3.5, "alarms.journal", role="viewer", alarm="level_hi"),
    ]
    run = await simulate(tmp_path, plant(LEVELS), steps, 4)
    assert run.transitions() == [(1.1, "activated", "unacknowledged"), (2.1, "cleared", "returned"), (3.05, "acknowledged", "normal")]
    snapshots = [event.data["alarm"] for event in run.events]
    assert [(s.priority.value, s.severity) for s in snapshots] == [("critical", 900)] * 3
    assert [s.message for s in snapshots] == ["level at 97 m (hihi 95)", "level at 50 m (hihi 95)", "level at 50 m (hihi 95)"]
    results = {(at, command): result for at, command, result in run.results}
    while_active, returned = results[(1.5, "alarms.summary")], results[(2.5, "alarms.summary")]
    assert while_active["most_severe_unacknowledged"]["priority"] == "critical"
    worst = returned["most_severe_unacknowledged"]
    assert (worst["state"], worst["priority"], worst["severity"], worst["message"], worst["value"]) == (
        "returned", "critical", 900, "level at 50 m (hihi 95)", 50.0)
    [listed] = results[(2.5, "alarms.list")]
    assert (listed["priority"], listed["severity"], listed["message"]) == ("critical", 900, "level at 50 m (hihi 95)")
    rows = results[(3.5, "alarms.journal")]
    assert [(row["transition"], row["priority"], row["severity"], row["message"], row["value"]) for row in rows] == [
        ("acknowledged", "critical", 900, "level at 50 m (hihi 95)", "50.0"),
        ("cleared", "critical", 900, "level at 50 m (hihi 95)", "50.0"),
        ("activated", "critical", 900, "level at 97 m (hihi 95)", "97.0"),
    ]


async def test_a_level_change_then_a_clear_keeps_the_priority_of_the_level_that_cleared(tmp_path: Path) -> None:
    # hihi (critical) → hi (high, a less severe level: no re-alarm) → normal: the alarm returned from hi.
    steps = [write(1.05, "level", 97), write(2.05, "level", 92), write(3.05, "level", 10)]
    run = await simulate(tmp_path, plant(LEVELS), steps, 4)
    assert [(t, s.priority.value, s.severity, s.message) for (_, t, _), s in zip(run.transitions(), (e.data["alarm"] for e in run.events))] == [
        ("activated", "critical", 900, "level at 97 m (hihi 95)"),
        ("level_changed", "high", 700, "level at 92 m (hi 90)"),
        ("cleared", "high", 700, "level at 10 m (hi 90)"),
    ]


async def test_the_opc_ua_event_of_the_clear_keeps_the_severity(tmp_path: Path) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(plant(LEVELS))
    config = load_config(path)
    state_dir = tmp_path / "state"
    state_dir.mkdir()
    add_users(state_dir)
    clock = SimClock(speed=20.0)  # simulated, paced so the client's requests get the loop
    runtime = Runtime(config, clock, state_dir=state_dir, retain=False)
    for adapter in build_adapters(config, None):
        if adapter.name == "alarms":
            runtime.add_adapter(adapter)
    server = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/"))
    runtime.add_adapter(server)
    await runtime.start()
    try:
        connection = Client(server.endpoint, timeout=4)
        connection.set_user("viewer")
        connection.set_password(PASSWORDS["viewer"])
        async with connection:
            seen: list[dict[str, Any]] = []

            class Handler:
                def event_notification(self, event: Any) -> None:
                    seen.append({name: variant.Value for name, variant in event.get_event_props_as_fields_dict().items()})

            subscription = await connection.create_subscription(10, Handler())
            await subscription.subscribe_events(connection.nodes.server, [connection.get_node(ua.NodeId(ua.ObjectIds.LimitAlarmType))])
            await clock.sleep(0.5)
            runtime.db.submit([("level", 97.0)], DRIVER)
            await _until(lambda: any(f["ActiveState/Id"] for f in seen))
            await clock.sleep(0.5)
            runtime.db.submit([("level", 50.0)], DRIVER)
            await _until(lambda: any(not f["ActiveState/Id"] for f in seen))
        activated, cleared = seen
        assert (activated["Severity"], activated["Message"].Text) == (900, "level at 97 m (hihi 95)")
        assert (cleared["Severity"], cleared["LastSeverity"], cleared["Message"].Text) == (900, 900, "level at 50 m (hihi 95)")
        assert cleared["AckedState/Id"] is False and cleared["Retain"] is True
    finally:
        await runtime.stop()


async def _until(condition: Any, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "no such event in time"
        await asyncio.sleep(0.01)
