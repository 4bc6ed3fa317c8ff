"""Fault reaction (`on_fault:` hold / initial / safe values), applied by the very cycle in which a
program faults; and restarts after a fault that make no false edges in function blocks."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock
from softplc.core.roles import Role
from softplc.core.tagdb import Origin

CORE = REPO / "tests" / "core_programs.py"
ENGINEER = Origin("hmi", "erin", role=Role.ENGINEER)

VALVE = f"""
version: 1
tags:
  demand: {{type: bool, initial: true}}
  armed: {{type: bool}}
  overflow: {{type: bool}}
  valve: {{type: bool}}
  pump: {{type: bool}}
  speed: {{type: float32, min: 0, max: 100}}
  scans: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: fill
        program: "{CORE}:FillValve"
        bind: {{demand: demand, armed: armed, overflow: overflow, valve: valve, pump: pump, speed: speed, scans: scans}}
        on_fault: ON_FAULT
      - {{name: watch, program: "{CORE}:Watcher", bind: {{value: valve}}}}
"""


@pytest.fixture
def plant(make_config, tmp_path: Path) -> Callable[[str], Runtime]:
    def build(on_fault: str, text: str = VALVE) -> Runtime:
        return Runtime(make_config(text.replace("ON_FAULT", on_fault)), SimClock(), state_dir=tmp_path / "state")

    return build


def changes(runtime: Runtime) -> list[tuple[float, str, Any]]:
    """Every committed change of a plant tag, with the runtime time at which it was committed."""
    seen: list[tuple[float, str, Any]] = []
    runtime.db.on_change(lambda tags: seen.extend((runtime.clock.now(), t.name, t.value) for t in tags if not t.name.startswith("_sys")))
    return seen


async def fault_at_110ms(runtime: Runtime, key: str = "armed") -> list[tuple[float, str, Any]]:
    """Run until the fill valve is open, make `fill` fault in the 110 ms cycle; return the changes of that cycle."""
    seen = changes(runtime)
    await runtime.start()
    clock, db = runtime.clock, runtime.db
    await clock.sleep_until(0.105)
    assert (db.value("valve"), db.value("pump"), db.value("speed"), db.value("scans")) == (True, True, 50.0, 11)
    db.submit([(key, True)], "test")
    await clock.sleep_until(0.115)
    assert runtime.program("fill").state.value == "FAULTED"
    return [(name, value) for time, name, value in seen if time == pytest.approx(0.11) and name != key]


async def test_hold_keeps_the_last_values_committed(plant) -> None:
    runtime = plant("hold")
    try:
        at_fault = await fault_at_110ms(runtime)
        db = runtime.db
        assert at_fault == []  # the faulting scan's outputs are discarded and nothing is set
        assert (db.value("valve"), db.value("pump"), db.value("speed"), db.value("scans")) == (True, True, 50.0, 11)
    finally:
        await runtime.stop()


async def test_initial_sets_every_output_back_in_the_cycle_of_the_fault_and_leaves_inouts(plant) -> None:
    runtime = plant("initial")
    try:
        at_fault = await fault_at_110ms(runtime)
        db = runtime.db
        assert sorted(at_fault) == [("pump", False), ("speed", 0.0), ("valve", False)]
        assert db.value("scans") == 11  # an InOut is the program's state: held
        # the program after it in the same task saw the closed valve in that very cycle
        assert runtime.program("watch").program.seen[-2:] == [(pytest.approx(0.10), True), (pytest.approx(0.11), False)]
        # a client may open it again by hand: the reaction was applied once, not every cycle
        db.submit([("valve", True)], "operator")
        await runtime.clock.sleep_until(0.2)
        assert db.value("valve") is True
    finally:
        await runtime.stop()


async def test_safe_values_are_set_and_the_other_outputs_hold(plant) -> None:
    runtime = plant("{safe: {valve: false, speed: 5, scans: 1000}}")
    try:
        at_fault = await fault_at_110ms(runtime)
        assert sorted(at_fault) == [("scans", 1000), ("speed", 5.0), ("valve", False)]
        assert runtime.db.value("pump") is True
    finally:
        await runtime.stop()


async def test_safe_values_with_the_others_initial(plant) -> None:
    runtime = plant("{safe: {speed: 5}, others: initial}")
    try:
        at_fault = await fault_at_110ms(runtime)
        assert sorted(at_fault) == [("pump", False), ("speed", 5.0), ("valve", False)]
    finally:
        await runtime.stop()


async def test_an_invalid_output_faults_with_the_same_reaction(plant) -> None:
    runtime = plant("{safe: {valve: false}}")
    try:
        at_fault = await fault_at_110ms(runtime, key="overflow")
        assert at_fault == [("valve", False)]  # not the speed of 150 the program tried to write
        assert "speed: out of range: 150.0 is above the maximum 100" in runtime.program("fill").error
        assert runtime.db.value("speed") == 50.0
    finally:
        await runtime.stop()


async def test_a_forced_output_stays_forced(plant) -> None:
    runtime = plant("initial")
    try:
        await runtime.start()
        await runtime.commands.call("tags.force", {"tag": "valve", "value": True}, ENGINEER)
        await runtime.clock.sleep_until(0.055)
        runtime.db.submit([("armed", True)], "test")
        await runtime.clock.sleep_until(0.1)
        assert runtime.program("fill").state.value == "FAULTED"
        assert runtime.db.value("valve") is True and runtime.db["valve"].forced  # forcing wins
        assert runtime.db.value("pump") is False
    finally:
        await runtime.stop()


async def test_a_setup_failing_at_start_up_applies_the_reaction_before_the_first_cycle(plant) -> None:
    text = f"""
version: 1
tags:
  out: {{type: int32, initial: 3}}
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: bad_setup, program: "{CORE}:BadSetup", bind: {{out: out}}, on_fault: ON_FAULT}}
"""
    runtime = plant("{safe: {out: -1}}", text)
    await runtime.start()
    try:
        assert runtime.program("bad_setup").state.value == "FAULTED"
        assert runtime.db.value("out") == -1
    finally:
        await runtime.stop()


async def test_a_failing_automatic_restart_applies_the_reaction_again(plant) -> None:
    text = VALVE.replace("        on_fault: ON_FAULT", "        on_fault: {safe: {valve: false}}\n        restart: {delay: 100ms, max: 2}")
    runtime = plant("", text)
    try:
        await fault_at_110ms(runtime)
        runtime.db.submit([("valve", True)], "operator")  # opened by hand while the program is faulted
        await runtime.clock.sleep_until(0.205)
        assert runtime.db.value("valve") is True
        await runtime.clock.sleep_until(0.215)  # restarted at 0.21 s, faulted again in that scan
        fill = runtime.program("fill")
        assert (fill.restarts, fill.faults, runtime.db.value("valve")) == (1, 2, False)
    finally:
        await runtime.stop()


EDGES = f"""
version: 1
tags:
  part: {{type: bool, initial: true}}
  armed: {{type: bool}}
  edges: {{type: uint32}}
  counted: {{type: uint32}}
  pulses: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: counter
        program: "{CORE}:EdgeCounter"
        bind: {{part: part, armed: armed, edges: edges, counted: counted, pulses: pulses}}
        RESTART
"""


def counts(runtime: Runtime) -> tuple[int, int, int]:
    return runtime.db.value("edges"), runtime.db.value("counted"), runtime.db.value("pulses")


async def test_reset_faults_makes_no_false_edge_for_a_signal_high_across_the_fault(plant) -> None:
    """The issue's case: after reset_faults, the edge detector counted a part that never arrived."""
    runtime = plant("", EDGES.replace("RESTART", "restart: never"))
    clock, db = runtime.clock, runtime.db
    await runtime.start()
    try:
        await clock.sleep_until(0.05)
        assert counts(runtime) == (1, 1, 1)  # a cold start follows IEC: a part present at start counts
        db.submit([("armed", True)], "test")
        await clock.sleep_until(0.1)
        assert runtime.program("counter").state.value == "FAULTED"
        db.submit([("armed", False)], "test")
        await clock.sleep_until(0.2)
        done = await runtime.commands.call("runtime.reset_faults", {}, Origin("hmi", "otto", role=Role.OPERATOR))
        assert done == "reset 1 faulted program: counter"
        await clock.sleep_until(0.5)
        program = runtime.program("counter").program
        assert program.restarted and not program.first_scan
        assert counts(runtime) == (1, 1, 1)  # the part was there all along: no new edge
        db.submit([("part", False)], "test")
        await clock.sleep_until(0.6)
        db.submit([("part", True)], "test")
        await clock.sleep_until(0.7)
        assert counts(runtime) == (2, 2, 2)  # a real edge still counts
    finally:
        await runtime.stop()


async def test_an_automatic_restart_makes_no_false_edge(plant) -> None:
    runtime = plant("", EDGES.replace("RESTART", "restart: {delay: 100ms, max: 3}"))
    clock, db = runtime.clock, runtime.db
    await runtime.start()
    try:
        await clock.sleep_until(0.05)
        db.submit([("armed", True)], "test")
        await clock.sleep_until(0.1)
        db.submit([("armed", False)], "test")
        await clock.sleep_until(0.5)
        counter = runtime.program("counter")
        assert (counter.state.value, counter.restarts, counter.program.setups) == ("RUNNING", 1, 2)
        assert counts(runtime) == (1, 1, 1)
    finally:
        await runtime.stop()


def test_blocks_created_by_a_warm_start_take_their_first_input_as_memory() -> None:
    from softplc import CTD, CTU, F_TRIG, R_TRIG, TP
    from softplc.core.function_blocks import warm_start

    clock = SimClock()

    def first_calls() -> list[bool]:
        rising, falling, up, down, pulse = R_TRIG(), F_TRIG(), CTU(PV=1), CTD(PV=1), TP(clock, PT=1.0)
        down.CV = 1  # a high CD is then a count down to 0 (cold) or the memory (warm)
        return [rising(CLK=True), falling(CLK=False), up(CU=True), down(CD=True), pulse(IN=True)]

    assert first_calls() == [True, False, True, True, True]  # cold start: IEC, memory FALSE
    with warm_start():
        warm = first_calls()
    assert warm == [False, False, False, False, False]
    with warm_start():
        falling = F_TRIG()
    assert falling(CLK=True) is False and falling(CLK=False) is True  # a warm memory of TRUE, then a real edge


async def test_a_stall_applies_the_reaction_as_soon_as_the_stuck_scan_returns(make_config, tmp_path: Path) -> None:
    import asyncio
    import time

    from softplc.core.clock import RealClock

    text = f"""
version: 1
tags:
  armed: {{type: bool}}
  done: {{type: uint32}}
runtime: {{stall_after: 200ms}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: block
        program: "{CORE}:Blocker"
        bind: {{armed: armed, done: done}}
        params: {{block: 0.5, once: true}}
        on_fault: {{safe: {{done: 99}}}}
"""
    runtime = Runtime(make_config(text), RealClock(), state_dir=tmp_path / "state")
    seen: list[Any] = []
    runtime.db.on_change(lambda tags: seen.extend((t.name, t.value) for t in tags if t.name == "done"))
    await runtime.start()
    try:
        runtime.db.submit([("armed", True)], "test")
        deadline = time.monotonic() + 10
        while runtime.program("block").state.value != "FAULTED":
            assert time.monotonic() < deadline, "the stall was not noticed"
            await asyncio.sleep(0.01)
        assert runtime.program("block").error.startswith("task fast is stuck in program block for ")
        # the stuck scan's own output was committed by its cycle, then the reaction at once
        assert seen == [("done", 1), ("done", 99)] and runtime.db.value("done") == 99
    finally:
        await runtime.stop()
