"""The alarm engine on the simulated clock, transition by transition (table-driven).

Each case is a plant with one alarm, a script of tag writes and operator actions at simulated
times, and the (time, transition, state) of every event it must publish — no more, no less.
Writes made at t.x5 s are applied at the next 100 ms scan boundary, where alarms are evaluated.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from tests.alarms_support import Step, bad, call, good, plant, simulate, write


@dataclass(frozen=True)
class Case:
    id: str
    alarm: str
    steps: tuple[Step, ...]
    expected: tuple[tuple[float, str, str], ...]
    duration: float = 10.0


LEVEL_HI = "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}}"
LEVEL_HI_LATCH = "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}, latch: true}"

CASES = [
    Case("activate-acknowledge-clear", LEVEL_HI,
         (write(1.05, "level", 95), call(2.05, "alarms.acknowledge", alarm="level_hi"), write(3.05, "level", 10)),
         ((1.1, "activated", "unacknowledged"), (2.05, "acknowledged", "acknowledged"), (3.1, "cleared", "normal"))),
    Case("return-unacknowledged-then-acknowledge", LEVEL_HI,
         (write(1.05, "level", 95), write(2.05, "level", 10), call(3.05, "alarms.acknowledge", alarm="level_hi")),
         ((1.1, "activated", "unacknowledged"), (2.1, "cleared", "returned"), (3.05, "acknowledged", "normal"))),
    Case("returned-reactivates", LEVEL_HI,
         (write(1.05, "level", 95), write(2.05, "level", 10), write(3.05, "level", 99)),
         ((1.1, "activated", "unacknowledged"), (2.1, "cleared", "returned"), (3.1, "activated", "unacknowledged"))),
    Case("latched-until-reset", LEVEL_HI_LATCH,
         (write(1.05, "level", 95), call(2.05, "alarms.acknowledge", alarm="level_hi"), write(3.05, "level", 10),
          call(4.05, "alarms.acknowledge", alarm="level_hi")),
         ((1.1, "activated", "unacknowledged"), (2.05, "acknowledged", "acknowledged"), (3.1, "cleared", "latched"),
          (4.05, "acknowledged", "normal"))),
    Case("latched-unacknowledged-reactivates", LEVEL_HI_LATCH,
         (write(1.05, "level", 95), write(2.05, "level", 10), write(3.05, "level", 95)),
         ((1.1, "activated", "unacknowledged"), (2.1, "cleared", "latched"), (3.1, "activated", "unacknowledged"))),
    Case("escalation-realarms-deescalation-does-not",
         "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90, hihi: 95}}",
         (write(1.05, "level", 91), call(2.05, "alarms.acknowledge", alarm="level_hi"), write(3.05, "level", 97),
          call(4.05, "alarms.acknowledge", alarm="level_hi"), write(5.05, "level", 92), write(6.05, "level", 50)),
         ((1.1, "activated", "unacknowledged"), (2.05, "acknowledged", "acknowledged"), (3.1, "realarmed", "unacknowledged"),
          (4.05, "acknowledged", "acknowledged"), (5.1, "level_changed", "acknowledged"), (6.1, "cleared", "normal"))),
    Case("low-limits", "definitions:\n  - {name: pressure_lo, limit: {tag: pressure, lo: 10, lolo: 5}}",
         (write(1.05, "pressure", 8), write(2.05, "pressure", 3), write(3.05, "pressure", 20)),
         ((1.1, "activated", "unacknowledged"), (2.1, "realarmed", "unacknowledged"), (3.1, "cleared", "returned"))),
    Case("deadband-holds-then-clears", "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90, deadband: 5}}",
         (write(1.05, "level", 90), write(2.05, "level", 86), write(3.05, "level", 85.5), write(4.05, "level", 85)),
         ((1.1, "activated", "unacknowledged"), (4.1, "cleared", "returned"))),
    Case("on-delay-filters-a-short-excursion", "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}, on_delay: 2s}",
         (write(1.05, "level", 95), write(2.05, "level", 10), write(4.05, "level", 95)),
         ((6.1, "activated", "unacknowledged"),)),
    Case("off-delay-holds-the-alarm", "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}, off_delay: 3s}",
         (write(1.05, "level", 95), write(2.05, "level", 10), write(3.05, "level", 95), write(4.05, "level", 10)),
         ((1.1, "activated", "unacknowledged"), (7.1, "cleared", "returned"))),
    Case("timed-shelving-expires-while-active",  LEVEL_HI,
         (write(1.05, "level", 95), call(2.05, "alarms.shelve", alarm="level_hi", reason="sensor being replaced", duration="3s")),
         ((1.1, "activated", "unacknowledged"), (2.05, "shelved", "shelved"), (5.1, "shelving_expired", "unacknowledged"))),
    Case("timed-shelving-hides-a-return-to-normal", LEVEL_HI,
         (write(1.05, "level", 95), call(2.05, "alarms.shelve", alarm="level_hi", reason="known", duration=5),
          write(3.05, "level", 10), write(4.05, "level", 97), call(5.05, "alarms.unshelve", alarm="level_hi")),
         ((1.1, "activated", "unacknowledged"), (2.05, "shelved", "shelved"), (3.1, "cleared", "shelved"),
          (4.1, "activated", "shelved"), (5.05, "unshelved", "unacknowledged"))),
    Case("one-shot-shelving-ends-at-return-to-normal", LEVEL_HI,
         (write(1.05, "level", 95), call(2.05, "alarms.shelve", alarm="level_hi", reason="flapping", one_shot=True),
          write(3.05, "level", 10), write(4.05, "level", 95)),
         ((1.1, "activated", "unacknowledged"), (2.05, "shelved", "shelved"), (3.1, "cleared", "shelved"),
          (3.1, "shelving_expired", "normal"), (4.1, "activated", "unacknowledged"))),
    Case("one-shot-shelving-also-ends-at-shelve-max",
         "shelve_max: 4s\ndefinitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}}",
         (write(1.05, "level", 95), call(2.05, "alarms.shelve", alarm="level_hi", reason="flapping", one_shot=True)),
         ((1.1, "activated", "unacknowledged"), (2.05, "shelved", "shelved"), (6.1, "shelving_expired", "unacknowledged"))),
    Case("suppressed-by-design", "definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}, suppress_when: not running}",
         (write(1.05, "running", False), write(2.05, "level", 95), write(3.05, "running", True), write(4.05, "running", False),
          write(5.05, "level", 10), write(6.05, "running", True)),
         ((1.1, "suppressed", "suppressed"), (2.1, "activated", "suppressed"), (3.1, "unsuppressed", "unacknowledged"),
          (4.1, "suppressed", "suppressed"), (5.1, "cleared", "suppressed"), (6.1, "unsuppressed", "normal"))),
    Case("out-of-service-by-an-engineer", LEVEL_HI,
         (write(1.05, "level", 95), call(2.05, "alarms.out_of_service", role="engineer", alarm="level_hi", reason="transmitter removed"),
          write(3.05, "level", 10), write(4.05, "level", 96), call(5.05, "alarms.in_service", role="engineer", alarm="level_hi")),
         ((1.1, "activated", "unacknowledged"), (2.05, "removed_from_service", "out_of_service"), (3.1, "cleared", "out_of_service"),
          (4.1, "activated", "out_of_service"), (5.05, "returned_to_service", "unacknowledged"))),
    Case("discrete-value", "definitions:\n  - {name: nav_failed, discrete: {tag: navstate, value: failed}}",
         (write(1.05, "navstate", "moving"), write(2.05, "navstate", "failed"), write(3.05, "navstate", "idle")),
         ((2.1, "activated", "unacknowledged"), (3.1, "cleared", "returned"))),
    Case("discrete-normal-value", "definitions:\n  - {name: stopped, discrete: {tag: running, normal: true}}",
         (write(1.05, "running", False), write(2.05, "running", True)),
         ((1.1, "activated", "unacknowledged"), (2.1, "cleared", "returned"))),
    Case("discrete-bad-quality", "definitions:\n  - {name: level_lost, discrete: {tag: level, bad_quality: true}, priority: high}",
         (bad(1.05, "level"), good(2.05, "level")),
         ((1.1, "activated", "unacknowledged"), (2.1, "cleared", "returned"))),
    Case("condition-over-tags", "definitions:\n  - {name: both_full, condition: t01_iBL >= 95 and t02_iBL >= 95}",
         (write(1.05, "t01_iBL", 96), write(2.05, "t02_iBL", 97), write(3.05, "t01_iBL", 50)),
         ((2.1, "activated", "unacknowledged"), (3.1, "cleared", "returned"))),
    Case("increase-within-a-window", "definitions:\n  - {name: overruns, increase: {tag: counter, by: 2, within: 3s}}",
         (write(1.05, "counter", 1), write(2.05, "counter", 2), write(6.05, "counter", 3), write(8.05, "counter", 5)),
         ((2.1, "activated", "unacknowledged"), (4.1, "cleared", "returned"), (8.1, "activated", "unacknowledged"))),
    Case("active-at-start", "definitions:\n  - {name: level_lo, limit: {tag: level, lo: 10}}",
         (write(1.05, "level", 50),),
         ((0.0, "activated", "unacknowledged"), (1.1, "cleared", "returned"))),
    Case("comment-is-journaled-as-an-action", LEVEL_HI,
         (write(1.05, "level", 95), call(2.05, "alarms.comment", alarm="level_hi", comment="operator on the way")),
         ((1.1, "activated", "unacknowledged"), (2.05, "commented", "unacknowledged"))),
]


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
async def test_alarm_transitions_on_the_simulated_clock(case: Case, tmp_path) -> None:
    run = await simulate(tmp_path, plant(case.alarm), case.steps, case.duration)
    refused = [result for result in run.results if isinstance(result[2], str) and result[2].startswith("refused")]
    assert not refused
    assert run.transitions() == list(case.expected)


async def test_a_simulated_run_gives_the_same_alarm_history_every_time(tmp_path) -> None:
    steps = [write(t + 0.05, "level", value) for t, value in enumerate([50, 95, 97, 91, 80, 96, 10, 95, 99, 20])]
    text = plant("definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90, hihi: 96, deadband: 2}, on_delay: 500ms}")
    first = await simulate(tmp_path / "a", text, steps, 12) if (tmp_path / "a").mkdir() is None else None
    second = await simulate(tmp_path / "b", text, steps, 12) if (tmp_path / "b").mkdir() is None else None
    assert first is not None and second is not None
    assert first.transitions() and first.transitions() == second.transitions()
    assert [event.data["alarm"].message for event in first.events] == [event.data["alarm"].message for event in second.events]


async def test_a_plant_without_tasks_evaluates_its_alarms_every_100_ms(tmp_path) -> None:
    head = """
    version: 1
    tags:
      level: {type: float64}
    """
    text = plant("definitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}, on_delay: 1s}", head=head)
    run = await simulate(tmp_path, text, (write(1.05, "level", 95), write(3.05, "level", 10)), 5)
    assert run.transitions() == [(2.1, "activated", "unacknowledged"), (3.1, "cleared", "returned")]
