"""Scan semantics on the simulated clock: consistent images, the write journal, output
visibility, absolute deadlines, priorities."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock

CORE = REPO / "tests" / "core_programs.py"


@pytest.fixture
def sim_runtime(make_config, tmp_path: Path) -> Callable[[str], Runtime]:
    def build(text: str) -> Runtime:
        return Runtime(make_config(text), SimClock(), state_dir=tmp_path / "state")

    return build


def program(runtime: Runtime, name: str) -> Any:
    """The user object of a program instance (to read what it recorded)."""
    return runtime.program(name).program


def is_multiple(t: float, interval: float) -> bool:
    k = round(t / interval)
    return math.isclose(t, k * interval, abs_tol=1e-9)


PAIR = f"""
version: 1
tags:
  a: {{type: int32}}
  b: {{type: int32}}
  checks_fast: {{type: uint32}}
  checks_odd: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: check_fast
        program: {CORE}:PairChecker
        bind: {{a: a, b: b, checks: checks_fast}}
  odd:
    interval: 7ms
    programs:
      - name: check_odd
        program: {CORE}:PairChecker
        bind: {{a: a, b: b, checks: checks_odd}}
"""


async def test_a_program_never_sees_half_of_an_external_write(sim_runtime) -> None:
    runtime = sim_runtime(PAIR)
    db, clock = runtime.db, runtime.clock
    applied: list[float] = []
    db.on_change(lambda tags: applied.extend(clock.now() for tag in tags if tag.name == "a"))
    submitted: list[tuple[float, int]] = []
    await runtime.start()
    try:
        for n in range(1, 301):
            # 3.1 ms apart, never on a 7 or 10 ms boundary: writes land between and across cycles
            await clock.sleep_until(n * 0.0031 + 0.00037)
            before = db.value("a")
            assert db.submit([("a", n), ("b", -n)], "client") == [None, None]
            assert db.value("a") == before and db.journal_length >= 2  # journaled, not applied
            submitted.append((clock.now(), n))
        await clock.sleep(0.02)
    finally:
        await runtime.stop()
    for name in ("check_fast", "check_odd"):
        assert runtime.program(name).state.value == "RUNNING", runtime.program(name).error
        seen = program(runtime, name).seen
        assert len(seen) > 50
        for t, a, _ in seen:
            # exactly the latest pair submitted before the cycle began: applied at the boundary
            expected = max((n for when, n in submitted if when < t), default=0)
            assert a == expected, f"{name} at {t}: saw {a}, expected {expected}"
    # every change of `a` happened at the start of a cycle of one of the two tasks
    assert len(applied) > 150
    assert all(is_multiple(t, 0.01) or is_multiple(t, 0.007) for t in applied)


async def test_writes_in_one_gap_are_applied_together_in_arrival_order(sim_runtime) -> None:
    runtime = sim_runtime(PAIR)
    db, clock = runtime.db, runtime.clock
    await runtime.start()
    try:
        await clock.sleep_until(0.0105)  # after the 10 ms cycle, before the 14 ms one
        db.submit([("a", 5)], "client 1")
        db.submit([("b", -7)], "client 2")  # half of a pair in separate submits...
        await clock.sleep_until(0.0110)
        db.submit([("a", 7), ("b", -7)], "client 1")  # ...completed before the next boundary
        await clock.sleep_until(0.0141)
        assert (db.value("a"), db.value("b")) == (7, -7)
        # applied (and time-stamped) at the start of the `odd` task's cycle at 14 ms
        epoch = clock.wall() - clock.now()
        assert math.isclose(db["a"].timestamp, epoch + 0.014, abs_tol=1e-9)
        assert db["a"].quality.value == "good"
    finally:
        await runtime.stop()
    assert runtime.program("check_odd").state.value == "RUNNING"


async def test_rejected_items_do_not_block_valid_ones(sim_runtime) -> None:
    runtime = sim_runtime(PAIR)
    db = runtime.db
    await runtime.start()
    try:
        results = db.submit([("a", 3), ("nope", 1), ("b", "x"), ("b", -3)], "client")
        assert results[0] is None and results[3] is None
        assert results[1].rule.value == "unknown tag" and results[2].rule.value == "type mismatch"
        await runtime.clock.sleep(0.011)
        assert (db.value("a"), db.value("b")) == (3, -3)
    finally:
        await runtime.stop()


VISIBILITY = f"""
version: 1
tags:
  c: {{type: uint32}}
  copy: {{type: uint32}}
  copy_of_copy: {{type: uint32}}
tasks:
  producer:
    interval: 10ms
    priority: 0
    programs:
      - {{name: before, program: "{CORE}:Watcher", bind: {{value: c}}}}
      - {{name: count, program: "{CORE}:Counter", bind: {{count: c}}}}
      - {{name: after, program: "{CORE}:Watcher", bind: {{value: c}}}}
      - {{name: follow, program: "{CORE}:Follower", bind: {{source: c, target: copy}}}}
  same_time:
    interval: 10ms
    priority: 1
    programs:
      - {{name: other_task, program: "{CORE}:Watcher", bind: {{value: c}}}}
      - {{name: follow2, program: "{CORE}:Follower", bind: {{source: copy, target: copy_of_copy}}}}
  slower:
    interval: 25ms
    priority: 2
    programs:
      - {{name: slow_task, program: "{CORE}:Watcher", bind: {{value: c}}}}
"""


async def test_outputs_are_visible_to_later_programs_and_the_next_tasks_cycle(sim_runtime) -> None:
    runtime = sim_runtime(VISIBILITY)
    await runtime.run(duration=0.2)
    # cycle k of `producer` at k * 10 ms makes c = k + 1
    before, after = program(runtime, "before").seen, program(runtime, "after").seen
    assert len(before) == len(after) == 20
    for k, ((t1, seen_before), (t2, seen_after)) in enumerate(zip(before, after)):
        assert t1 == t2 and is_multiple(t1, 0.01)
        assert seen_before == k  # a program before the producer sees the previous cycle's value
        assert seen_after == k + 1  # a program after it sees this cycle's output
    # the task due at the same time with a lower priority runs next and sees this cycle's output
    assert [v for _, v in program(runtime, "other_task").seen] == list(range(1, 21))
    # a 25 ms task sees the output of the producer's latest cycle (the same instant included)
    for t, value in program(runtime, "slow_task").seen:
        assert value == math.floor(t / 0.01 + 1e-9) + 1
    assert runtime.db.value("c") == 20
    assert runtime.db.value("copy") == 20 and runtime.db.value("copy_of_copy") == 20


OVERRIDE = f"""
version: 1
tags:
  x: {{type: int32}}
  force: {{type: bool}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: override
        program: {CORE}:Overrider
        bind: {{value: x, force: force}}
"""


async def test_a_program_writing_the_same_tag_in_that_cycle_wins(sim_runtime) -> None:
    runtime = sim_runtime(OVERRIDE)
    db, clock = runtime.db, runtime.clock
    await runtime.start()
    try:
        await clock.sleep_until(0.0155)
        db.submit([("x", 5)], "client")
        await clock.sleep_until(0.0255)
        assert db.value("x") == 5  # no override: the client value stays
        db.submit([("x", 6), ("force", True)], "client")
        await clock.sleep_until(0.0355)
    finally:
        await runtime.stop()
    seen = program(runtime, "override").seen
    # the program saw the client's 6 at the 30 ms cycle (the journal comes first), then wrote 100
    assert seen[:4] == [0, 0, 5, 6]
    assert db.value("x") == 100


DEADLINES = f"""
version: 1
tags:
  n3: {{type: uint32}}
  n10: {{type: uint32}}
  n1s: {{type: uint32}}
tasks:
  t3:
    interval: 3ms
    programs: [{{name: c3, program: "{CORE}:Counter", bind: {{count: n3}}}}]
  t10:
    interval: 10ms
    programs: [{{name: c10, program: "{CORE}:Counter", bind: {{count: n10}}}}]
  t1s:
    interval: 1s
    programs: [{{name: c1s, program: "{CORE}:Counter", bind: {{count: n1s}}}}]
"""


async def test_releases_are_on_absolute_deadlines(sim_runtime) -> None:
    runtime = sim_runtime(DEADLINES)
    await runtime.run(duration=30.0)
    for name, interval, cycles in (("c3", 0.003, 10000), ("c10", 0.01, 3000), ("c1s", 1.0, 30)):
        times = program(runtime, name).times
        assert len(times) == cycles
        # origin + k * interval, computed afresh each cycle: no drift after thousands of cycles
        assert all(t == k * interval for k, t in enumerate(times)), name
    for task in runtime.tasks:
        stats = task.stats
        assert stats.overruns == 0 and stats.latency.max == 0.0
        assert stats.cycle.mean == pytest.approx(task.interval)
    assert runtime.db.value("_sys.t3.cycles") == 10000 - 166  # published every 0.5 s: at 29.5 s
    assert runtime.db.value("_sys.t10.interval_ms") == 10.0


PRIORITIES = f"""
version: 1
tags:
  ta: {{type: uint32}}
  tb: {{type: uint32}}
  tc: {{type: uint32}}
tasks:
  low:
    interval: 20ms
    priority: 9
    programs: [{{name: low, program: "{CORE}:Counter", bind: {{count: ta}}}}]
  high:
    interval: 10ms
    priority: 0
    programs: [{{name: high, program: "{CORE}:Counter", bind: {{count: tb}}}}]
  middle:
    interval: 40ms
    priority: 3
    programs: [{{name: middle, program: "{CORE}:Counter", bind: {{count: tc}}}}]
"""


async def test_tasks_due_at_the_same_time_run_in_priority_order(sim_runtime) -> None:
    runtime = sim_runtime(PRIORITIES)
    task_of = {"ta": "low", "tb": "high", "tc": "middle"}
    by_time: dict[float, list[str]] = {}
    # each task's outputs are committed at the end of its cycle: the commits show the order
    runtime.db.on_change(
        lambda tags: [by_time.setdefault(round(runtime.clock.now(), 6), []).append(task_of[t.name]) for t in tags if t.name in task_of]
    )
    await runtime.run(duration=0.2)
    assert by_time[0.0] == ["high", "middle", "low"]
    assert by_time[0.02] == ["high", "low"]
    assert by_time[0.04] == ["high", "middle", "low"]
    assert by_time[0.01] == ["high"]
    assert len(by_time) == 20


def test_a_callback_registered_last_runs_after_every_other_whenever_they_were_registered(sim_runtime) -> None:
    # A redundant pair captures the state at a boundary after every adapter's work there (the
    # alarms evaluated on that cycle's tags), though it registers first.
    engine = sim_runtime("version: 1\ntags:\n  x: {type: int32}\n").engine
    calls: list[str] = []
    undo_capture = engine.after_cycle(lambda task: calls.append("capture"), last=True)
    engine.after_cycle(lambda task: calls.append("alarms"))
    undo_history = engine.after_cycle(lambda task: calls.append("history"))
    engine.after_cycle(lambda task: calls.append("final"), last=True)
    for callback in engine._after_cycle:  # noqa: SLF001 - the order the engine calls them in
        callback(None)
    assert calls == ["alarms", "history", "capture", "final"]
    undo_history()
    undo_capture()
    engine.after_cycle(lambda task: calls.append("late"))
    calls.clear()
    for callback in engine._after_cycle:  # noqa: SLF001
        callback(None)
    assert calls == ["alarms", "late", "final"]
