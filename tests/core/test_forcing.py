"""Forcing with the CODESYS semantics, through the core: image, commit, clients, drivers, restart."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock
from softplc.core.commands import CommandRefused
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule

CORE = REPO / "tests" / "core_programs.py"
ENGINEER = Origin("hmi", user="erin", role=Role.ENGINEER)
OPERATOR = Origin("hmi", user="otto", role=Role.OPERATOR)
DRIVER = Origin("fleet:r01", role=None)

PLANT = f"""
version: 1
tags:
  source: {{type: int32, min: -1000, max: 1000}}
  copy:   {{type: int32}}
  count:  {{type: uint32, retain: true}}
  pose:   {{type: float64, access: ro}}
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: follow, program: "{CORE}:Follower", bind: {{source: source, target: copy}}}}
      - {{name: count, program: "{CORE}:Counter", bind: {{count: count}}}}
"""


def build(make_config, state: Path) -> Runtime:
    return Runtime(make_config(PLANT), SimClock(), state_dir=state)


async def test_programs_read_the_forced_value_and_their_writes_to_it_are_dropped(make_config, tmp_path: Path) -> None:
    runtime = build(make_config, tmp_path / "state")
    db, clock, commands = runtime.db, runtime.clock, runtime.commands
    await runtime.start()
    try:
        db.submit([("source", 5)], OPERATOR)
        await clock.sleep_until(0.05)
        assert db.value("copy") == 5
        # A program's input forced: the program reads the forced value.
        await commands.call("tags.force", {"tag": "source", "value": "42"}, ENGINEER)
        await clock.sleep_until(0.1)
        assert db.value("source") == 42 and db["source"].forced and db.value("copy") == 42
        # A program's output forced: its writes do not reach the tag (nor anyone who reads it).
        await commands.call("tags.force", {"tag": "copy", "value": -7}, ENGINEER)
        changes: list[int] = []
        db.on_change(lambda tags: changes.extend(t.value for t in tags if t.name == "copy"))
        counted = db.value("count")
        await commands.call("tags.force", {"tag": "count", "value": 1}, ENGINEER)
        await clock.sleep_until(0.2)
        assert db.value("copy") == -7 and changes == [-7]
        assert db.value("count") == 1  # the Counter kept incrementing its image; nothing reached the tag
        # A client's write to a forced tag is refused, with the rule; a driver's is dropped.
        [refused] = db.submit([("source", 9)], OPERATOR)
        assert refused is not None and refused.rule is Rule.FORCED
        assert db.submit([("pose", 1.5)], DRIVER) == [None]
        await commands.call("tags.force", {"tag": "pose", "value": 3.25}, ENGINEER)
        await clock.sleep_until(0.25)
        db.submit([("pose", 1.5)], DRIVER)
        await clock.sleep_until(0.3)
        assert db.value("pose") == 3.25
        await clock.sleep_until(0.6)
        assert db.value("_sys.forced") == 4
        listed = await commands.call("tags.forces", {}, Origin("hmi", role=Role.VIEWER))
        assert [(f["tag"], f["value"], f["by"]) for f in listed] == [
            ("source", 42, "hmi:erin"), ("copy", -7, "hmi:erin"), ("count", 1, "hmi:erin"), ("pose", 3.25, "hmi:erin")]
        # unforce: the value stays until its owner writes it; unforce-and-restore: back to before.
        await commands.call("tags.unforce", {"tag": "copy"}, ENGINEER)
        await commands.call("tags.unforce", {"tag": "pose", "restore": True}, ENGINEER)
        await commands.call("tags.unforce", {"tag": "count", "restore": "true"}, ENGINEER)
        await clock.sleep_until(0.305 + 0.3)
        assert not db["copy"].forced and db.value("copy") == 42  # the program writes it again
        assert db.value("pose") == 1.5  # the value it had when forced
        assert db.value("count") > counted  # restored, then counting again
        await clock.sleep_until(1.01)  # system tags are published twice a second
        assert db.value("_sys.forced") == 1
    finally:
        await runtime.stop()


async def test_who_may_force_and_what_cannot_be_forced(make_config, tmp_path: Path) -> None:
    runtime = build(make_config, tmp_path / "state")
    commands = runtime.commands
    with pytest.raises(CommandRefused, match="role operator may not force tags"):
        await commands.call("tags.force", {"tag": "source", "value": 1}, OPERATOR)
    with pytest.raises(CommandRefused, match="source: out of range: 5000 is above the maximum 1000"):
        await commands.call("tags.force", {"tag": "source", "value": 5000}, ENGINEER)
    with pytest.raises(CommandRefused, match="type mismatch: expected int32, got 'lots'"):
        await commands.call("tags.force", {"tag": "source", "value": "lots"}, ENGINEER)
    with pytest.raises(CommandRefused, match="cannot be forced"):
        await commands.call("tags.force", {"tag": "_sys.state", "value": "RUNNING"}, ENGINEER)
    with pytest.raises(CommandRefused, match="nope: unknown tag"):
        await commands.call("tags.force", {"tag": "nope", "value": 1}, ENGINEER)
    with pytest.raises(CommandRefused, match="source is not forced"):
        await commands.call("tags.unforce", {"tag": "source"}, ENGINEER)


async def test_forces_do_not_survive_a_restart_and_are_never_retained(make_config, tmp_path: Path, caplog) -> None:
    state = tmp_path / "state"
    runtime = build(make_config, state)
    await runtime.start()
    await runtime.clock.sleep_until(0.1)
    counted = runtime.db.value("count")
    await runtime.commands.call("tags.force", {"tag": "count", "value": 999}, ENGINEER)
    await runtime.clock.sleep_until(0.2)
    assert runtime.db.value("count") == 999
    await runtime.stop()
    assert "1 forced tag released by the stop (forces are not retained): count" in caplog.text
    again = build(make_config, state)
    await again.start()
    try:
        assert not again.db.forces and not again.db["count"].forced
        assert again.db.value("count") in range(counted, counted + 3)  # the last unforced value, not 999
    finally:
        await again.stop()
