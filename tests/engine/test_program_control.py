"""Program control while the plant runs: programs.list / start / stop / restart (engineer role)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock
from softplc.core.commands import CommandRefused
from softplc.core.roles import Role
from softplc.core.tagdb import Origin

CORE = REPO / "tests" / "core_programs.py"
ENGINEER = Origin("hmi", "erin", "127.0.0.1", role=Role.ENGINEER)
OPERATOR = Origin("opcua", "otto", role=Role.OPERATOR)
VIEWER = Origin("opcua", "vera", role=Role.VIEWER)

PLANT = f"""
version: 1
tags:
  demand: {{type: bool, initial: true}}
  armed: {{type: bool}}
  valve: {{type: bool}}
  pump: {{type: bool}}
  speed: {{type: float32, min: 0, max: 100}}
  scans: {{type: uint32}}
  part: {{type: bool, initial: true}}
  edges: {{type: uint32}}
  counted: {{type: uint32}}
  pulses: {{type: uint32}}
  n: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: fill
        program: "{CORE}:FillValve"
        bind: {{demand: demand, armed: armed, valve: valve, pump: pump, speed: speed, scans: scans}}
        on_fault: {{safe: {{valve: false}}, others: initial}}
      - name: counter
        program: "{CORE}:EdgeCounter"
        bind: {{part: part, armed: armed, edges: edges, counted: counted, pulses: pulses}}
  slow:
    interval: 100ms
    programs:
      - {{name: count, program: "{CORE}:Counter", bind: {{count: n}}}}
      - {{name: spare_fill, program: "{CORE}:Follower", bind: {{source: demand, target: valve}}, enabled: false}}
"""


@pytest.fixture
async def plant(make_config, tmp_path: Path) -> Any:
    runtime = Runtime(make_config(PLANT), SimClock(), state_dir=tmp_path / "state")
    calls: list[Any] = []
    runtime.commands.on_call(calls.append)
    runtime.calls = calls  # type: ignore[attr-defined]
    await runtime.start()
    yield runtime
    await runtime.stop()


async def call(runtime: Runtime, name: str, origin: Origin = ENGINEER, **arguments: Any) -> Any:
    return await runtime.commands.call(name, arguments, origin)


async def test_programs_list_shows_each_program_with_its_state_and_the_actions_it_allows(plant: Runtime) -> None:
    await plant.clock.sleep_until(0.05)
    listing = await call(plant, "programs.list", VIEWER)  # any role may look
    by_name = {entry["name"]: entry for entry in listing}
    assert list(by_name) == ["fill", "counter", "count", "spare_fill"]
    fill = by_name["fill"]
    assert fill["task"] == "fast" and fill["state"] == "RUNNING" and fill["actions"] == ["stop", "restart"]
    assert fill["program"] == f"{CORE}:FillValve" and fill["version"] == 1 and fill["faults"] == 0
    assert fill["on_fault"] == {"safe": {"valve": False}, "others": "initial"} and fill["restart"] == "never"
    assert fill["bind"]["valve"] == "valve"
    assert by_name["spare_fill"]["state"] == "STOPPED" and by_name["spare_fill"]["actions"] == ["start", "restart"]
    assert plant.calls == []  # reading is not audited


async def test_stop_applies_the_fault_reaction_and_start_resumes_warm(plant: Runtime) -> None:
    clock, db = plant.clock, plant.db
    await clock.sleep_until(0.05)
    assert (db.value("valve"), db.value("pump"), db.value("edges")) == (True, True, 1)
    done = await call(plant, "programs.stop", program="fill")
    assert done == "stopped program fill: its outputs took its fault reaction ({'safe': {'valve': False}, 'others': 'initial'})"
    # committed at once, before any other cycle
    assert (db.value("valve"), db.value("pump"), db.value("speed")) == (False, False, 0.0)
    scans = db.value("scans")
    await call(plant, "programs.stop", program="counter")
    await clock.sleep_until(0.2)
    assert db.value("scans") == scans and plant.program("fill").state.value == "STOPPED"
    assert db.value("_sys.fast.fill.state") == "STOPPED"
    with pytest.raises(CommandRefused, match="program fill is already STOPPED"):
        await call(plant, "programs.stop", program="fill")
    done = await call(plant, "programs.start", program="counter")
    assert done == "started program counter (warm start: setup() ran; scanned from the next cycle of task fast)"
    await call(plant, "programs.start", program="fill")
    await clock.sleep_until(0.3)
    assert db.value("valve") is True and db.value("scans") > scans
    assert (db.value("edges"), db.value("counted"), db.value("pulses")) == (1, 1, 1)  # part high all along: no false edge
    assert plant.program("counter").program.setups == 2
    with pytest.raises(CommandRefused, match="program fill is already RUNNING"):
        await call(plant, "programs.start", program="fill")
    # every call, carried out or refused, reached the command listeners (the audit trail) with its origin
    assert [(c.command, c.arguments["program"], c.accepted) for c in plant.calls] == [
        ("programs.stop", "fill", True), ("programs.stop", "counter", True), ("programs.stop", "fill", False),
        ("programs.start", "counter", True), ("programs.start", "fill", True), ("programs.start", "fill", False),
    ]
    assert {str(c.origin) for c in plant.calls} == {"hmi:erin@127.0.0.1"}


async def test_restart_runs_setup_again_without_false_edges(plant: Runtime) -> None:
    await plant.clock.sleep_until(0.05)
    done = await call(plant, "programs.restart", program="counter")
    assert done == "restarted program counter (warm start: setup() ran again)"
    await plant.clock.sleep_until(0.2)
    counter = plant.program("counter")
    assert counter.program.setups == 2 and counter.program.restarted
    assert (plant.db.value("edges"), plant.db.value("counted"), plant.db.value("pulses")) == (1, 1, 1)


async def test_start_of_one_faulted_program_leaves_the_others_faulted(plant: Runtime) -> None:
    plant.db.submit([("armed", True)], "test")
    await plant.clock.sleep_until(0.05)
    assert plant.program("fill").state.value == "FAULTED" and plant.program("counter").state.value == "FAULTED"
    plant.db.submit([("armed", False)], "test")
    await plant.clock.sleep_until(0.1)
    listing = {entry["name"]: entry for entry in await call(plant, "programs.list")}
    assert listing["fill"]["actions"] == ["start", "stop", "restart"] and listing["fill"]["error"].startswith("RuntimeError: level sensor lost")
    await call(plant, "programs.start", program="fill")
    await plant.clock.sleep_until(0.2)
    assert plant.program("fill").state.value == "RUNNING" and plant.program("counter").state.value == "FAULTED"


async def test_only_an_engineer_controls_programs_and_mistakes_are_refused_clearly(plant: Runtime) -> None:
    with pytest.raises(CommandRefused, match="role operator may not stop programs"):
        await call(plant, "programs.stop", OPERATOR, program="fill")
    with pytest.raises(CommandRefused, match="role viewer may not restart programs"):
        await call(plant, "programs.restart", VIEWER, program="fill")
    with pytest.raises(CommandRefused, match=r"no program 'fil' \(did you mean 'fill'\?\); programs: fill, counter, count, spare_fill"):
        await call(plant, "programs.stop", program="fil")
    with pytest.raises(CommandRefused, match="give the program's name as 'program'"):
        await call(plant, "programs.start")
    assert plant.program("fill").state.value == "RUNNING"


async def test_starting_a_program_that_would_be_a_second_writer_is_refused(plant: Runtime) -> None:
    with pytest.raises(CommandRefused, match=r"starting program spare_fill would make two programs write 'valve' \(written by fill\)"):
        await call(plant, "programs.start", program="spare_fill")
    assert plant.program("spare_fill").state.value == "STOPPED"
    await call(plant, "programs.stop", program="fill")
    await call(plant, "programs.start", program="spare_fill")  # the other writer is stopped: allowed
    assert plant.program("spare_fill").state.value == "RUNNING"
