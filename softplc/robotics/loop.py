"""The control loop: an async task runs a robot's driver every cycle on the runtime clock (robots of one phase share a task).

Cycles are released on absolute deadlines (`start + k * cycle`); a cycle that ends after its
next release skips the missed ones and counts them as overruns, like a PLC task. Planning runs
through a `Planning` (a worker process in real time, inline on the simulated clock; see
`softplc.robotics.planning`) while the loop keeps cycling, so a 40 ms A* never stalls the robot
or the event loop.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

from softplc.core.clock import Clock
from softplc.robotics.driver import Command, PlanRequest, Report, RobotDriver
from softplc.robotics.peers import PeerView
from softplc.robotics.planner import Plan
from softplc.robotics.planning import ClockPlanning, Planning

log = logging.getLogger(__name__)


class DriverIO(Protocol):
    """Where a driver's inputs come from and its outputs go (tag database or OPC UA)."""

    def command(self) -> Command | None:
        """The goal tags now; None while they are unknown (then the robot holds still)."""
        ...

    def peers(self) -> PeerView: ...

    async def publish(self, report: Report) -> None: ...


@dataclass(frozen=True, slots=True)
class Sample:
    """One cycle of a robot's recorded trajectory."""

    t: float
    x: float
    y: float
    heading: float
    speed: float
    turn_rate: float
    navstate: str


@dataclass
class LoopStats:
    """Timing of one robot's control loop (real seconds for step times)."""

    cycles: int = 0
    overruns: int = 0
    step_total: float = 0.0
    step_max: float = 0.0
    plan_total: float = 0.0
    plan_max: float = 0.0
    plans: int = 0

    @property
    def step_mean(self) -> float:
        return self.step_total / self.cycles if self.cycles else 0.0


@dataclass
class ControlLoop:
    """Runs one driver forever: read inputs, step, publish, record."""

    driver: RobotDriver
    io: DriverIO
    clock: Clock
    cycle: float = 0.1
    phase: float = 0.0
    record: list[Sample] | None = None
    stats: LoopStats = field(default_factory=LoopStats)
    planning: Planning | None = None  # default: through the clock (inline when simulated, else a thread)

    _in_flight: asyncio.Task[Plan] | None = field(default=None, init=False, repr=False)
    _planning_serial: int = field(default=0, init=False, repr=False)

    async def run(self) -> None:
        await run_together([self], self.clock, self.cycle, self.phase)

    async def step(self) -> None:
        """One cycle: take a finished plan, read the inputs, step the driver, publish, record."""
        began = time.perf_counter()
        now = self.clock.now()
        in_flight = self._in_flight
        if in_flight is not None and in_flight.done():
            plan = in_flight.result() if not in_flight.cancelled() and in_flight.exception() is None else None
            if plan is None:
                error = None if in_flight.cancelled() else in_flight.exception()
                plan = Plan(False, reason=f"planner error: {error!r}")
            self._count_plan(plan.seconds)
            self.driver.plan_done(self._planning_serial, plan, now)
            self._in_flight = None
        command = self.io.command()
        if command is not None:
            report = self.driver.step(now, command, self.io.peers())
            request = self.driver.take_plan_request()
            if request is not None:
                if self._in_flight is not None:
                    self._in_flight.cancel()  # superseded: its result would be ignored anyway
                self._in_flight, self._planning_serial = self._plan(request), request.serial
            await self.io.publish(report)
            if self.record is not None:
                pose = self.driver.pose
                self.record.append(Sample(now, pose.x, pose.y, pose.heading, report.speed, report.turn_rate, report.navstate.value))
        stats = self.stats
        stats.cycles += 1
        spent = time.perf_counter() - began
        stats.step_total += spent
        stats.step_max = max(stats.step_max, spent)

    def _plan(self, request: PlanRequest) -> asyncio.Task[Plan]:
        planning = self.planning or ClockPlanning(self.clock)
        return asyncio.ensure_future(planning.run(request))

    def _count_plan(self, seconds: float) -> None:
        self.stats.plans += 1
        self.stats.plan_total += seconds
        self.stats.plan_max = max(self.stats.plan_max, seconds)


async def run_together(loops: Sequence[ControlLoop], clock: Clock, cycle: float, phase: float = 0.0) -> None:
    """Run control loops of one cycle and phase in one task, forever: one wake-up a cycle for all of them.

    Each cycle steps every loop in order. A thousand robots in ten phases are then ten wake-ups
    a cycle, not a thousand: each wake-up of a task costs the event loop about as much as a
    robot's step. A cycle that ends after the next release skips the missed ones and counts them
    as overruns of every loop of the group.
    """
    origin = clock.now() + phase
    k = 0
    while True:
        await clock.sleep_until(origin + k * cycle)
        for loop in loops:
            await loop.step()
        k += 1
        late = clock.now() - (origin + k * cycle)
        if late > 0:
            missed = math.floor(late / cycle) + 1
            for loop in loops:
                loop.stats.overruns += missed
            k += missed
