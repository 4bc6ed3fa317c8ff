"""A standby runtime that mirrors an active one state by state, then takes over without a reset.

Two runtimes of one plant in one process, on one simulated clock whose standby's view is shifted
by 1000 s (two machines' clocks never agree): the active captures its state at every cycle
boundary, the standby applies each state (through the plain data the plant API hands out), and
when the active stops the standby takes over — timers, edges, counters, random draws, forces and
the writes the active had acknowledged but not yet applied all carry on.
"""

from __future__ import annotations

import asyncio
import copy
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest

from softplc.app.runtime import Runtime
from softplc.config import PlantConfig
from softplc.core.clock import Clock, SimClock
from softplc.core.plant import StateRefused
from softplc.core.plant_role import PlantRole, RoleTerm
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule
from softplc.core.tags import Quality

T = TypeVar("T")
OPERATOR = Origin("opcua", "olga", "127.0.0.1", role=Role.OPERATOR)
ENGINEER = Origin("cli", "erin", "127.0.0.1", role=Role.ENGINEER)

PLANT = """
version: 1
tags:
  part: {type: bool, initial: true}
  scans: {type: uint32}
  edges: {type: uint32}
  done: {type: bool}
  draw: {type: float64}
  setpoint: {type: float64, retain: true}
  spare: {type: uint32}
  locked: {type: uint32}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: stateful
        program: tests.engine.replication_programs:Stateful
        bind: {part: part, scans: scans, edges: edges, done: done, draw: draw}
      - name: locked
        program: tests.engine.replication_programs:Unpicklable
        bind: {scans: locked}
"""


class Shifted(Clock):
    """Another machine's view of the same simulated time: its clock reads 1000 s more (no driver of its own)."""

    def __init__(self, base: SimClock, shift: float = 1000.0) -> None:
        self.base = base
        self.shift = shift

    def now(self) -> float:
        return self.base.now() + self.shift

    def wall(self) -> float:
        return self.base.wall()

    async def sleep_until(self, deadline: float) -> None:
        await self.base.sleep_until(deadline - self.shift)

    async def run_blocking(self, function: Callable[..., T], *args: Any) -> T:
        return function(*args)

    @property
    def simulated(self) -> bool:
        return True


def wire(state: Any) -> Any:
    """What crosses a link: a deep copy (nothing shared between the two runtimes)."""
    return copy.deepcopy(state)


class Pair:
    """An active runtime whose every captured state and journal batch is applied to a standby."""

    def __init__(self, config: PlantConfig, tmp_path: Path) -> None:
        self.clock = SimClock()  # driven by the test: a runtime that stops must not stop time for the other
        self.active = Runtime(config, Shifted(self.clock, 0.0), state_dir=tmp_path / "a", retain=False)
        self.standby = Runtime(config, Shifted(self.clock), state_dir=tmp_path / "b", retain=False)
        self.standby.role.set(RoleTerm(PlantRole.STANDBY, 1, active="a", detail="this runtime (b) is the standby: write to the active, a"))
        self.active.role.set(RoleTerm(PlantRole.ACTIVE, 1, active="a"))
        self.linked = True
        self.sent = 0
        active = self.active.plant.replication
        active.on_journal(self._journal)
        self.active.plant.after_cycle(self._cycle, last=True)
        self._send(active.capture_full())

    def _send(self, state: Any) -> None:
        if self.linked:
            self.standby.plant.replication.apply(wire(state))
            self.sent += 1

    def _cycle(self, task: Any) -> None:
        self._send(self.active.plant.replication.capture(task))

    def _journal(self, message: list[Any]) -> None:
        if self.linked:
            self.standby.plant.replication.hold(wire(message))

    async def start(self) -> None:
        await self.active.start()
        await self.standby.start()
        self.driver = asyncio.ensure_future(self.clock.drive())

    async def fail_over(self) -> int:
        """The active is gone: the standby becomes active (epoch 2) and resumes its journal."""
        self.linked = False
        await self.active.stop()
        resumed = self.standby.plant.replication.take_over()
        self.standby.role.set(RoleTerm(PlantRole.ACTIVE, 2, active="b"))
        return resumed

    async def stop(self) -> None:
        await self.active.stop()
        await self.standby.stop()
        self.driver.cancel()


@pytest.fixture
async def pair(make_config: Callable[[str], PlantConfig], tmp_path: Path) -> Any:
    pair = Pair(make_config(PLANT), tmp_path)
    await pair.start()
    yield pair
    await pair.stop()


async def test_a_standby_scans_nothing_and_mirrors_the_active_cycle_by_cycle(pair: Pair) -> None:
    await pair.clock.sleep_until(0.205)
    active, standby = pair.active, pair.standby
    assert active.db.value("scans") == 21 and standby.db.value("scans") == 21
    assert standby.tasks[0].stats.cycles == 0 and standby.engine.passed > 0  # it never scanned
    assert standby.db.value("draw") == active.db.value("draw") != 0.0
    mirrored = standby.program("stateful").program
    assert mirrored.edge_count == 1 and mirrored.random.getstate() == active.program("stateful").program.random.getstate()
    # its programs' time is the active's (its own clock reads 1000 s more)
    assert abs(standby.program_clock.now() - active.program_clock.now()) < 1e-9
    assert standby.clock.now() - active.clock.now() == pytest.approx(1000.0)


async def test_a_standby_refuses_writes_naming_the_active_and_the_refusal_is_reported(pair: Pair) -> None:
    standby = pair.standby
    heard: list[Any] = []
    standby.db.on_write(heard.extend)
    (refused,) = standby.db.submit([("spare", 5)], OPERATOR)
    assert refused is not None and refused.rule is Rule.NOT_ACTIVE and "write to the active, a" in refused.detail
    assert heard[0].rule is Rule.NOT_ACTIVE and heard[0].origin.user == "olga"
    assert standby.db.submit([("spare", 5)], Origin("fleet", role=None))[0].rule is Rule.NOT_ACTIVE  # a driver's: dropped
    with pytest.raises(Exception) as forced:
        standby.db.force("spare", 3, ENGINEER)
    assert getattr(forced.value, "rule", None) is Rule.NOT_ACTIVE
    assert standby.db.journal_length == 0


async def test_the_standby_takes_over_without_a_reset_timers_edges_and_draws_carry_on(pair: Pair) -> None:
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.155)
    program = active.program("stateful").program
    started, scans = program.started, active.db.value("scans")
    assert active.db.value("done") is False and scans == 16
    expected_draws = copy.deepcopy(program.random)
    await pair.fail_over()
    await pair.clock.sleep_until(0.505)
    successor = standby.program("stateful").program
    # the timer started on the old active fires 0.35 s after that start, on the new one
    assert successor.done_at is not None and successor.done_at - started == pytest.approx(0.35, abs=0.011)
    assert standby.db.value("done") is True
    assert successor.edge_count == 1 and standby.db.value("edges") == 1  # no false edge of `part`, high throughout
    assert standby.db.value("scans") == scans + standby.tasks[0].stats.cycles  # one count per cycle, no cycle lost or doubled
    expected = [expected_draws.random() for _ in range(standby.tasks[0].stats.cycles)]
    assert standby.db.value("draw") == expected[-1]  # the random sequence went on where it was


async def test_a_write_acknowledged_by_the_active_but_not_applied_is_applied_by_the_successor(pair: Pair) -> None:
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.055)
    assert active.db.submit([("spare", 42), ("setpoint", 2.5)], OPERATOR) == [None, None]  # acknowledged: Good
    assert active.db.journal_length == 2
    assert await pair.fail_over() == 2  # the active died before its next cycle applied them
    await pair.clock.sleep_until(0.085)
    assert standby.db.value("spare") == 42 and standby.db.value("setpoint") == 2.5


async def test_a_quality_change_journaled_by_the_active_keeps_the_value_on_the_successor(pair: Pair) -> None:
    # A link's quality change carries no value (the tag keeps the one it has when applied): it
    # crosses the sync link as such, never as a value of its own.
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.055)
    assert active.db.submit([("spare", 7)], OPERATOR) == [None]
    active.db.submit_quality(["spare"], Quality.UNCERTAIN, "link:plc2")
    assert await pair.fail_over() == 2
    await pair.clock.sleep_until(0.085)
    assert standby.db.value("spare") == 7
    assert standby.db.get("spare").quality is Quality.UNCERTAIN


async def test_the_actives_own_status_in_its_journal_never_reaches_the_standby_and_keeps_the_positions(pair: Pair) -> None:
    # An adapter's `_sys.` status (a link's state, Sparkplug's counters) is that runtime's own: a
    # batch of it alone is not sent, and among plant writes it only keeps its place.
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.055)
    sent: list[Any] = []
    undo = active.plant.replication.on_journal(sent.append)
    driver = Origin("links", role=None)
    assert active.db.submit([("_sys.fast.overruns", 9)], driver) == [None]
    assert sent == []
    assert active.db.submit([("_sys.fast.overruns", 10), ("spare", 5)], driver) == [None, None]
    undo()
    assert [item[0] for item in sent[0][2]] == ["-", "w"]
    assert await pair.fail_over() == 1  # the plant's write only, at its own position
    await pair.clock.sleep_until(0.085)
    assert standby.db.value("spare") == 5


async def test_forces_are_mirrored_and_stay_in_effect_after_the_takeover(pair: Pair) -> None:
    active, standby = pair.active, pair.standby
    active.db.force("spare", 9, ENGINEER)
    await pair.clock.sleep_until(0.035)
    assert standby.db.get("spare").forced and standby.db.value("spare") == 9
    assert [force.tag for force in standby.db.forces.active()] == ["spare"]
    active.db.unforce("spare")
    await pair.clock.sleep_until(0.055)
    assert not standby.db.get("spare").forced and len(standby.db.forces) == 0
    active.db.force("spare", 11, ENGINEER)
    await pair.clock.sleep_until(0.075)
    await pair.fail_over()
    assert standby.db.submit([("spare", 1)], OPERATOR)[0].rule is Rule.FORCED


async def test_a_program_whose_state_cannot_be_copied_is_named_and_starts_from_its_own_setup(pair: Pair) -> None:
    await pair.clock.sleep_until(0.055)
    assert "locked" in pair.active.plant.replication.unpicklable  # type: ignore[attr-defined]
    assert pair.standby.db.value("locked") == pair.active.db.value("locked")  # its outputs are mirrored all the same


async def test_states_out_of_order_or_malformed_are_refused_and_nothing_is_applied(pair: Pair) -> None:
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.055)
    pair.linked = False
    await pair.clock.sleep_until(0.075)
    door = standby.plant.replication
    before = standby.db.value("scans")
    with pytest.raises(StateRefused, match="out of order"):
        door.apply(active.plant.replication.capture(active.tasks[0]))
    state = active.plant.replication.capture_full()
    for broken, reason in (
        (["state", *state[1:6], [["nope", 1, "good", 0.0]], *state[7:]], "no replicated tag 'nope'"),
        (["state", *state[1:6], [["scans", "many", "good", 0.0]], *state[7:]], "scans"),
        (["state", *state[1:6], [["_sys.state", "RUNNING", "good", 0.0]], *state[7:]], "_sys.state"),
        (["state", *state[1:6], [["scans", 1, "excellent", 0.0]], *state[7:]], "quality"),
        (state[:5], "expected a list of 10"),
        ("hello", "expected a list"),
    ):
        with pytest.raises(StateRefused, match=reason):
            door.apply(broken)
    # a program state naming a function to call (the classic pickle attack) is refused
    evil = _os_system_pickle()
    programs = [[*image[:7], evil] if image[0] == "stateful" else image for image in state[8]]
    with pytest.raises(StateRefused, match="not allowed"):
        door.apply([*state[:8], programs, state[9]])
    assert standby.db.value("scans") == before  # nothing of any of them was applied
    door.apply(state)  # a full state brings it back in step
    assert standby.db.value("scans") == active.db.value("scans")


def _os_system_pickle() -> bytes:
    class Evil:
        def __reduce__(self) -> Any:
            import os

            return (os.system, ("echo pwned",))

    return pickle.dumps({"edge_count": Evil()})
