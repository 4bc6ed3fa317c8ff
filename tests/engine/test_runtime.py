"""The runtime on the simulated clock: faults and restarts, operator resets, invalid outputs,
system tags, retained tags, --until, reproducibility."""

from __future__ import annotations

import asyncio
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from softplc.core.commands import CommandRefused
from softplc.core.expression import Condition
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality

CORE = REPO / "tests" / "core_programs.py"


@pytest.fixture
def sim_runtime(make_config, tmp_path: Path) -> Callable[..., Runtime]:
    def build(text: str, state_dir: Path | None = None) -> Runtime:
        return Runtime(make_config(text), SimClock(), state_dir=state_dir or tmp_path / "state")

    return build


FAULTS = f"""
version: 1
tags:
  armed: {{type: bool}}
  bomb_scans: {{type: uint32}}
  n_fast: {{type: uint32}}
  n_slow: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: bomb, program: "{CORE}:Bomb", bind: {{armed: armed, scans: bomb_scans}}}}
      - {{name: count, program: "{CORE}:Counter", bind: {{count: n_fast}}}}
  slow:
    interval: 100ms
    programs:
      - {{name: slow_count, program: "{CORE}:Counter", bind: {{count: n_slow}}}}
"""


async def test_a_raising_program_is_faulted_and_everything_else_keeps_scanning(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    db, clock = runtime.db, runtime.clock
    await runtime.start()
    try:
        await clock.sleep_until(0.105)
        db.submit([("armed", True)], "test")
        await clock.sleep_until(0.6)
        bomb = runtime.program("bomb")
        assert bomb.state.value == "FAULTED" and bomb.faults == 1
        assert bomb.error.startswith("ZeroDivisionError: armed and dangerous at ")
        assert bomb.error.endswith(f"{CORE}:{_line_of('armed and dangerous')}")
        assert db.value("bomb_scans") == 11  # 0..100 ms; the 110 ms scan raised, nothing after
        # visible in the system tags (published every 0.5 s)
        assert db.value("_sys.fast.bomb.state") == "FAULTED"
        assert db.value("_sys.fast.bomb.error") == bomb.error
        assert db.value("_sys.fast.bomb.faults") == 1
        assert db.value("_sys.fast.count.state") == "RUNNING"
        assert db.value("_sys.state") == "RUNNING"  # a program fault is not a runtime error
        # the program after it in the same task and the other task kept scanning
        assert db.value("n_fast") == 60 and db.value("n_slow") == 6
        # an operator disarms and resets the faults through the system tag, like any client
        db.submit([("armed", False), ("_sys.reset_faults", True)], "operator")
        await clock.sleep_until(1.005)
        assert bomb.state.value == "RUNNING" and type(bomb.program).setups == 2
        assert db.value("_sys.reset_faults") is False
        await clock.sleep_until(1.2)
        assert db.value("bomb_scans") == 11 + 20  # scanning again from the 1.01 s cycle
    finally:
        await runtime.stop()


async def test_reset_faults_is_a_command_an_operator_may_call_and_a_viewer_may_not(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    calls: list[Any] = []
    runtime.commands.on_call(calls.append)
    await runtime.start()
    try:
        runtime.db.submit([("armed", True)], "test")
        await runtime.clock.sleep_until(0.2)
        assert runtime.program("bomb").state.value == "FAULTED"
        runtime.db.submit([("armed", False)], "test")
        await runtime.clock.sleep_until(0.3)
        with pytest.raises(CommandRefused, match="role viewer may not reset program faults"):
            await runtime.commands.call("runtime.reset_faults", {}, Origin("hmi", "vera", role=Role.VIEWER))
        assert runtime.program("bomb").state.value == "FAULTED"
        done = await runtime.commands.call("runtime.reset_faults", {}, Origin("hmi", "otto", role=Role.OPERATOR))
        assert done == "reset 1 faulted program: bomb" and runtime.program("bomb").state.value == "RUNNING"
        assert [(c.origin.user, c.accepted) for c in calls] == [("vera", False), ("otto", True)]
    finally:
        await runtime.stop()


def _line_of(text: str) -> int:
    lines = CORE.read_text().splitlines()
    return next(i for i, line in enumerate(lines, 1) if text in line)


RESTART = f"""
version: 1
tags:
  armed: {{type: bool, initial: true}}
  bomb_scans: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: bomb
        program: {CORE}:Bomb
        bind: {{armed: armed, scans: bomb_scans}}
        restart: RESTART
"""


async def test_restart_policy_restarts_after_the_delay_at_most_max_restarts_times(sim_runtime) -> None:
    runtime = sim_runtime(RESTART.replace("RESTART", "{delay: 1s, max: 2}"))
    await runtime.run(duration=5.0)
    bomb = runtime.program("bomb")
    # faulted at 0 s, restarted (setup again) at 1 s and 2 s, faulting again each time; then it stays FAULTED
    assert bomb.program.setup_times == [0.0, 1.0, 2.0]
    assert (bomb.faults, bomb.restarts, bomb.state.value) == (3, 2, "FAULTED")
    assert runtime.db.value("_sys.fast.bomb.faults") == 3


async def test_restart_policy_stop_stays_faulted(sim_runtime) -> None:
    runtime = sim_runtime(RESTART.replace("RESTART", "never"))
    await runtime.run(duration=5.0)
    bomb = runtime.program("bomb")
    assert bomb.program.setup_times == [0.0]
    assert (bomb.faults, bomb.restarts, bomb.state.value) == (1, 0, "FAULTED")


async def test_restart_recovers_when_the_cause_is_gone(sim_runtime) -> None:
    runtime = sim_runtime(RESTART.replace("RESTART", "{delay: 1s, max: 2}"))
    db, clock = runtime.db, runtime.clock
    await runtime.start()
    try:
        await clock.sleep_until(0.5)
        db.submit([("armed", False)], "test")
        await clock.sleep_until(1.5)
    finally:
        await runtime.stop()
    bomb = runtime.program("bomb")
    assert (bomb.state.value, bomb.faults, bomb.restarts) == ("RUNNING", 1, 1)
    assert db.value("bomb_scans") == 50  # restarted at 1.0 s, scanned 1.00..1.49 s


BROKEN = f"""
version: 1
tags:
  out: {{type: int32}}
  exit_out: {{type: int32}}
  n: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: bad_setup, program: "{CORE}:BadSetup", bind: {{out: out}}}}
      - {{name: exiter, program: "{CORE}:Exiter", bind: {{out: exit_out}}}}
      - {{name: count, program: "{CORE}:Counter", bind: {{count: n}}}}
"""


async def test_setup_errors_and_sys_exit_fault_the_program_not_the_runtime(sim_runtime) -> None:
    runtime = sim_runtime(BROKEN)
    reason = await runtime.run(duration=1.0)
    assert "duration" in reason and runtime.error == ""
    setup = runtime.program("bad_setup")
    assert setup.state.value == "FAULTED"
    assert setup.error.startswith("RuntimeError: cannot initialise the widget at ")
    exiter = runtime.program("exiter")
    assert exiter.state.value == "FAULTED" and exiter.error.startswith("SystemExit: 3")
    assert runtime.db.value("n") == 100
    assert runtime.db.value("out") == 0


INVALID = f"""
version: 1
tags:
  mode: {{type: uint16}}
  good: {{type: int32}}
  bad: {{type: int16, max: 100}}
  pair_a: {{type: float64}}
  pair_b: {{type: float64}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: writer
        program: {CORE}:BadWriter
        bind: {{mode: mode, good: good, bad: bad, many: [pair_a, pair_b]}}
"""


@pytest.mark.parametrize(
    ("mode", "error"),
    [
        (1, "wrote an invalid value: bad: out of range: 200 is above the maximum 100"),
        (2, "wrote an invalid value: bad: type mismatch: expected int16, got str 'two hundred'"),
        (3, "wrote an invalid value: many: type mismatch: must stay a list of 2 values"),
    ],
)
async def test_an_invalid_output_faults_the_program_and_commits_none_of_its_outputs(sim_runtime, mode: int, error: str) -> None:
    runtime = sim_runtime(INVALID)
    db, clock = runtime.db, runtime.clock
    changes: list[tuple[float, str, Any]] = []
    await runtime.start()
    try:
        await clock.sleep_until(0.095)
        db.on_change(lambda tags: changes.extend((clock.now(), t.name, t.value) for t in tags if not t.name.startswith("_sys")))
        db.submit([("mode", mode)], "test")
        await clock.sleep_until(0.5)
    finally:
        await runtime.stop()
    writer = runtime.program("writer")
    assert (writer.state.value, writer.error) == ("FAULTED", error)
    # `good` counted 0..90 ms (10 scans); the 100 ms scan's outputs were all dropped
    assert db.value("good") == 10
    assert changes == [(0.1, "mode", mode)]
    assert db.value("bad") == 0 and db.value("pair_a") == 0.0


async def test_reset_stats_through_the_system_tag(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    db, clock = runtime.db, runtime.clock
    await runtime.start()
    try:
        await clock.sleep_until(0.75)
        assert db.value("_sys.fast.cycles") == 50
        db.submit([("_sys.reset_stats", True)], "operator")
        await clock.sleep_until(1.001)
        # executed when the system tags were published at 1.0 s, just before that instant's cycle
        assert db.value("_sys.reset_stats") is False
        stats = runtime.tasks[0].stats
        assert stats.cycles == 1 and stats.latency.count == 1  # only the 1.0 s cycle since the reset
        await clock.sleep_until(1.501)
        assert db.value("_sys.fast.cycles") == 50  # 1.00 .. 1.49 s, published at 1.5 s
    finally:
        await runtime.stop()


async def test_system_tags(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    db = runtime.db
    assert db.value("_sys.state") == ""
    await runtime.run(duration=2.2)
    assert db.value("_sys.state") == "RUNNING"  # as published last, at 2.0 s
    assert db.value("_sys.error") == ""
    assert db.value("_sys.time") == 2.0
    assert db.value("_sys.fast.interval_ms") == 10.0 and db.value("_sys.slow.interval_ms") == 100.0
    assert db.value("_sys.fast.cycles") == 200 and db.value("_sys.slow.cycles") == 20
    assert db.value("_sys.fast.overruns") == 0 and db.value("_sys.fast.watchdog_trips") == 0
    assert db.value("_sys.fast.cycle_ms_mean") == pytest.approx(10.0)
    assert db.value("_sys.fast.latency_ms_max") == 0.0 and db.value("_sys.fast.scan_ms_p99") == 0.0
    for name in ("_sys.state", "_sys.fast.cycles", "_sys.fast.bomb.state"):
        assert not db[name].definition.writable_by_clients
        assert db.validate(name, db.value(name), role=None) == db.value(name)
    rejected = db.submit([("_sys.fast.cycles", 0)], "client")[0]
    assert rejected is not None and rejected.rule.value == "read-only"


async def test_quality_and_timestamps(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    db, clock = runtime.db, runtime.clock
    epoch = clock.wall()
    await runtime.start()
    try:
        await clock.sleep_until(0.205)
        db.submit_quality(["armed", "n_slow"], Quality.BAD, "driver lost")
        assert db["armed"].quality is Quality.GOOD  # journaled like a value
        await clock.sleep_until(0.215)
        assert db["armed"].quality is Quality.BAD and db["armed"].timestamp == pytest.approx(epoch + 0.21)
        # a program's output is GOOD again when it is committed (the slow counter, at 0.3 s)
        assert db["n_slow"].quality is Quality.BAD
        await clock.sleep_until(0.305)
        assert db["n_slow"].quality is Quality.GOOD and db["n_slow"].timestamp == pytest.approx(epoch + 0.3)
        assert db["n_fast"].timestamp == pytest.approx(epoch + 0.3)
    finally:
        await runtime.stop()


async def test_until_stops_right_after_the_cycle_that_made_it_true(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    until = Condition("n_fast >= 37 or n_slow > 1000", runtime.db.names())
    reason = await runtime.run(until=until)
    assert reason == "condition met: n_fast >= 37 or n_slow > 1000"
    assert runtime.db.value("n_fast") == 37
    assert runtime.clock.now() == pytest.approx(0.36)


async def test_a_stop_requested_before_the_start_ends_the_run_at_once(sim_runtime) -> None:
    # An early Ctrl-C (before the event loop's handler is in place) is requested this way.
    runtime = sim_runtime(FAULTS)
    runtime.request_stop("interrupted (Ctrl-C)")
    reason = await asyncio.wait_for(runtime.run(), 10)
    assert reason == "interrupted (Ctrl-C)"
    assert runtime.clock.now() < 0.1


async def test_until_over_system_tags(sim_runtime) -> None:
    runtime = sim_runtime(FAULTS)
    until = Condition("_sys.slow.cycles >= 12 and _sys.state == 'RUNNING'", runtime.db.names())
    await runtime.run(until=until)
    assert runtime.clock.now() == pytest.approx(1.5)  # seen at the first publication after 1.1 s


RETAIN = """
version: 1
tags:
  total: {type: uint32, retain: true}
  setpoint: {type: float64, initial: 1.5, retain: true}
  name: {type: string, initial: none, retain: true}
  scratch: {type: int32, initial: 7}
tasks:
  fast:
    interval: 10ms
    programs:
      - {name: count, program: "CORE:Counter", bind: {count: total}}
""".replace("CORE", str(CORE))


async def test_retained_tags_survive_a_restart(sim_runtime, tmp_path: Path) -> None:
    state = tmp_path / "plant-state"
    first = sim_runtime(RETAIN, state)
    db, clock = first.db, first.clock
    await first.start()
    try:
        await clock.sleep_until(0.5)
        db.submit([("setpoint", 2.25), ("name", "batch 42"), ("scratch", 9)], "operator")
        await clock.sleep_until(1.55)
        # flushed once a second while running, in one transaction, to a real SQLite file
        with sqlite3.connect(state / "retain.sqlite") as connection:
            rows = dict(connection.execute("SELECT name, value FROM retain").fetchall())
        assert rows["setpoint"] == "2.25" and rows["name"] == '"batch 42"' and int(rows["total"]) >= 100
        assert "scratch" not in rows
        await clock.sleep_until(2.0)
    finally:
        await first.stop()
    total = first.db.value("total")
    assert total == 200

    second = sim_runtime(RETAIN, state)
    assert second.db.value("total") == 0  # restored when the runtime starts, not before
    await second.start()
    try:
        assert second.db.value("total") == total  # restored before the first cycle
        await second.clock.sleep(0.005)
        assert second.db.value("total") == total + 1  # and the first cycle counted on from there
        assert second.db.value("setpoint") == 2.25 and second.db.value("name") == "batch 42"
        assert second.db.value("scratch") == 7  # not retained: back to its initial value
    finally:
        await second.stop()


async def test_a_retained_value_that_no_longer_fits_its_type_falls_back_to_initial(sim_runtime, tmp_path: Path, caplog) -> None:
    state = tmp_path / "plant-state"
    first = sim_runtime(RETAIN, state)
    await first.start()
    first.db.submit([("setpoint", 1e10)], "operator")
    await first.clock.sleep(0.02)
    await first.stop()
    # the plant changes: setpoint becomes an int16
    second = sim_runtime(RETAIN.replace("{type: float64, initial: 1.5, retain: true}", "{type: int16, initial: 3, retain: true}"), state)
    await second.start()
    try:
        assert second.db.value("setpoint") == 3
        assert "retained value 10000000000.0 of setpoint (saved as float64) is refused: type mismatch: " in caplog.text
        assert "does not fit in int16" in caplog.text and "setpoint starts at its initial value 3" in caplog.text
    finally:
        await second.stop()


def _history(runtime: Runtime) -> list[tuple[float, str, Any]]:
    history: list[tuple[float, str, Any]] = []
    runtime.db.on_change(lambda tags: history.extend((runtime.clock.now(), t.name, t.value) for t in tags))
    return history


async def test_the_same_simulated_run_twice_gives_identical_histories(tmp_path: Path) -> None:
    histories = []
    for run in range(2):
        config = load_config(REPO / "tagdb.yaml")
        runtime = Runtime(config, SimClock(), state_dir=tmp_path / f"state{run}")
        history = _history(runtime)
        await runtime.run(duration=120.0)
        histories.append(history)
    first, second = histories
    assert len(first) > 500
    assert {name for _, name, _ in first} >= {"t01_iBM", "t02_iBL", "_sys.time"}
    assert first == second


async def test_identical_histories_with_client_writes(sim_runtime, tmp_path: Path) -> None:
    histories = []
    for run in range(2):
        runtime = sim_runtime(FAULTS, tmp_path / f"state{run}")
        history = _history(runtime)
        await runtime.start()
        clock = runtime.clock
        for step in range(1, 40):
            await clock.sleep(0.0137)
            runtime.db.submit([("armed", step % 7 == 0), ("_sys.reset_faults", step % 9 == 0)], "client")
        await clock.sleep(0.5)
        await runtime.stop()
        histories.append(history)
    assert len(histories[0]) > 100 and histories[0] == histories[1]


async def test_a_setup_failing_again_after_a_restart_waits_the_full_delay(sim_runtime) -> None:
    runtime = sim_runtime(
        BROKEN.replace("{name: bad_setup, program: \"" + str(CORE) + ":BadSetup\", bind: {out: out}}",
                       "{name: bad_setup, program: \"" + str(CORE) + ":BadSetup\", bind: {out: out}, restart: {max: 3}}")
    )
    instance = runtime.program("bad_setup")
    assert instance.restart.automatic and instance.restart.max_restarts == 3
    await runtime.start()
    try:
        await runtime.clock.sleep_until(2.5)
        assert (instance.restarts, instance.faults) == (2, 3)  # tried again at 1 s and 2 s only
        await runtime.clock.sleep_until(10)
        assert (instance.restarts, instance.faults, instance.state.value) == (3, 4, "FAULTED")
    finally:
        await runtime.stop()


async def test_numpy_outputs_are_stored_as_python_values(sim_runtime) -> None:
    runtime = sim_runtime(
        f"""
        version: 1
        tags:
          label: {{type: uint16}}
          flag: {{type: bool}}
          level: {{type: float64}}
        tasks:
          fast:
            interval: 10ms
            programs:
              - {{name: np, program: "{CORE}:NumpyWriter", bind: {{label: label, flag: flag, level: level}}}}
        """
    )
    await runtime.run(duration=0.05)
    assert runtime.program("np").state.value == "RUNNING", runtime.program("np").error
    values = [runtime.db.value(name) for name in ("label", "flag", "level")]
    assert values == [1, True, 0.25] and [type(v) for v in values] == [int, bool, float]


async def test_retained_values_are_saved_in_the_background_on_the_real_clock(make_config, tmp_path: Path) -> None:
    import asyncio
    import threading
    import time

    from softplc.core.clock import RealClock

    state = tmp_path / "real-state"
    runtime = Runtime(make_config(RETAIN), RealClock(), state_dir=state)
    saved_by: list[str] = []
    store_save = None
    await runtime.start()
    try:
        assert runtime.retained is not None and runtime.retained.store is not None
        store_save = runtime.retained.store.save

        def recording_save(values: dict) -> None:
            saved_by.append(threading.current_thread().name)
            store_save(values)

        runtime.retained.store.save = recording_save  # type: ignore[method-assign]
        runtime.db.submit([("setpoint", 7.5)], "operator")
        deadline = time.monotonic() + 10
        while not saved_by:  # flushed once a second
            assert time.monotonic() < deadline, "retained values were never saved"
            await asyncio.sleep(0.02)
        assert saved_by[0] != threading.main_thread().name  # the disk wait is off the event loop
    finally:
        await runtime.stop()
    with sqlite3.connect(state / "retain.sqlite") as connection:
        assert dict(connection.execute("SELECT name, value FROM retain").fetchall())["setpoint"] == "7.5"


async def test_simulated_time_stops_with_the_runtime(sim_runtime) -> None:
    """Stopping adapters takes real time; the simulated clock must not run on meanwhile."""
    import asyncio

    class SlowToStop:
        name = "slow"

        async def start(self, runtime: Runtime) -> None:
            pass

        async def stop(self) -> None:
            await asyncio.sleep(0.2)  # real I/O, e.g. a server closing its sockets

        def describe(self) -> str:
            return "slow to stop"

    runtime = sim_runtime(FAULTS)
    runtime.add_adapter(SlowToStop())
    published: list[float] = []
    runtime.db.on_change(lambda tags: published.extend(t.value for t in tags if t.name == "_sys.time"))
    await runtime.run(duration=3.0)
    assert runtime.clock.now() == 3.0
    assert max(published) <= 3.0


async def test_simulated_time_starts_when_every_adapter_has_started(sim_runtime) -> None:
    import asyncio

    class SlowToStart:
        name = "slow"

        def __init__(self) -> None:
            self.woke_at: float | None = None

        async def start(self, runtime: Runtime) -> None:
            runtime.spawn(self._background(runtime), "slow-background")
            await asyncio.sleep(0.2)  # real I/O, e.g. building an OPC UA address space

        async def _background(self, runtime: Runtime) -> None:
            await runtime.clock.sleep(1.0)  # e.g. a robot's control loop
            self.woke_at = runtime.clock.now()

        async def stop(self) -> None:
            pass

        def describe(self) -> str:
            return "slow to start"

    runtime = sim_runtime(FAULTS)
    adapter = SlowToStart()
    runtime.add_adapter(adapter)
    await runtime.run(duration=2.0)
    assert adapter.woke_at == 1.0
    assert runtime.tasks[0].stats.cycles == 200  # the plant scanned from t = 0
    assert runtime.program("count").program.times[0] == 0.0


async def test_identical_histories_with_the_default_plants_robots(tmp_path: Path) -> None:
    """The default plant with the adapters `softplc run --sim --no-servers` starts (the robots)."""
    import argparse

    from softplc.app.adapters import build_adapters

    histories = []
    for run in range(2):
        config = load_config(REPO / "tagdb.yaml")
        runtime = Runtime(config, SimClock(), state_dir=tmp_path / f"state{run}")
        for adapter in build_adapters(config, argparse.Namespace(no_servers=True)):
            runtime.add_adapter(adapter)
        history = _history(runtime)
        await runtime.start()
        try:
            await runtime.clock.sleep_until(1.0)  # a client sends r01 to task 1's source
            source = (config.tag("t01_src_x").initial, config.tag("t01_src_y").initial)
            assert runtime.db.submit([("r01_xgoal", source[0]), ("r01_ygoal", source[1]), ("r01_status", True)], "client") == [None] * 3
            await runtime.clock.sleep_until(40.0)
        finally:
            await runtime.stop()
        histories.append(history)
    first, second = histories
    assert any(name == "r01_xpos" for _, name, _ in first), "the robot never moved"
    assert first == second
