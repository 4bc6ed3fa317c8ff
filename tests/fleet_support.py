"""Helpers for the fleet tests: a small plant with robots on a map, run on the simulated clock."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from softplc.adapters.fleet.adapter import FleetAdapter
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import Clock, SimClock
from softplc.robotics.gridmap import OccupancyGrid

ROBOT_TEMPLATE = """\
version: 1
templates:
  robot:
    instances_from:
      file: robots.yaml
      initial: {xpos: start.x, ypos: start.y, heading: start.heading, xgoal: start.x, ygoal: start.y}
    tags:
      xpos:      {type: float64, access: ro}
      ypos:      {type: float64, access: ro}
      heading:   {type: float64, access: ro}
      speed:     {type: float64, access: ro}
      navstate:  {type: string, initial: idle, access: ro}
      navreason: {type: string, access: ro}
      radius:    {type: float64, access: ro}
      route:     {type: string, access: ro}
      status:    {type: bool}
      xgoal:     {type: float64}
      ygoal:     {type: float64}
      agent:     {type: string}
      report:    {type: string}
      online:    {type: bool, access: ro}
"""


def robot_yaml(robot_id: str, x: float, y: float, heading: float = 0.0, *, driver: str = "sim", size_mm: float = 255,
               speed: float = 0.2, turn: float = 0.4) -> str:
    return textwrap.dedent(f"""\
      - id: {robot_id}
        name: Robot {robot_id}
        driver: {driver}
        length_mm: {size_mm}
        width_mm: {size_mm}
        height_mm: 400
        load_capacity: 20
        max_linear_speed: {speed}
        max_angular_speed: {turn}
        hardware: [laser_range_finder, two_wheel_drive, gripper]
        start: {{x: {x}, y: {y}, heading: {heading}}}
    """)


def write_plant(directory: Path, robots: Sequence[str], extra: str = "") -> Path:
    """tagdb.yaml + robots.yaml in `directory`; returns the tagdb path."""
    (directory / "robots.yaml").write_text("robots:\n" + "".join(textwrap.indent(r, "  ") for r in robots))
    path = directory / "tagdb.yaml"
    path.write_text(ROBOT_TEMPLATE + extra)
    return path


class Plant:
    """A runtime with a fleet adapter (recording trajectories) on any clock."""

    def __init__(self, tagdb: Path, grid: OccupancyGrid, clock: Clock | None = None, **options: Any) -> None:
        self.config = load_config(tagdb)
        self.runtime = Runtime(self.config, clock or SimClock(), state_dir=tagdb.parent / "state")
        from softplc.robotics.robots import load_robots

        self.fleet = FleetAdapter(load_robots(tagdb.parent / "robots.yaml"), grid, record=True, **options)
        self.runtime.add_adapter(self.fleet)
        self.db = self.runtime.db
        self.clock = self.runtime.clock

    async def __aenter__(self) -> Plant:
        await self.runtime.start()
        return self

    async def __aexit__(self, *exc: Any) -> None:
        await self.runtime.stop()

    def send(self, robot_id: str, x: float, y: float) -> None:
        """Command a trip the way the thesis's sequencer does: goal and status busy together."""
        results = self.db.submit([(f"{robot_id}_xgoal", x), (f"{robot_id}_ygoal", y), (f"{robot_id}_status", True)], "test")
        assert results == [None, None, None], results

    async def trip(self, robot_id: str, x: float, y: float, limit: float) -> float:
        """Send a robot to (x, y) and wait until it is done (arrived or failed); the clock time taken."""
        start = self.clock.now()
        self.send(robot_id, x, y)
        await self.run_until(lambda: self.db.value(f"{robot_id}_status"), limit=1.0, step=0.01)  # the command landed
        await self.run_until(lambda: self.idle(robot_id), limit=limit)
        return self.clock.now() - start

    async def run_until(self, condition: Callable[[], bool], limit: float, step: float = 0.1) -> float:
        """Advance the clock until `condition()` holds; fail after `limit` clock seconds."""
        start = self.clock.now()
        while not condition():
            if self.clock.now() - start > limit:
                raise AssertionError(f"condition not met within {limit} s of clock time")
            await self.clock.sleep(step)
        return self.clock.now() - start

    def idle(self, *robot_ids: str) -> bool:
        return all(not self.db.value(f"{r}_status") and self.db.value(f"{r}_navstate") in ("arrived", "failed") for r in robot_ids)


def min_separation(plant: Plant, ids: Sequence[str]) -> tuple[float, float]:
    """The smallest centre distance minus the sum of radii over all recorded cycles, and when."""
    traces = {r: plant.fleet.trajectory(r) for r in ids}
    radius = {r: plant.fleet.robots[r].radius for r in ids}
    worst, when = math.inf, 0.0
    length = min(len(t) for t in traces.values())
    for i in range(length):
        for a_index, a in enumerate(ids):
            for b in ids[a_index + 1:]:
                sa, sb = traces[a][i], traces[b][i]
                gap = math.hypot(sa.x - sb.x, sa.y - sb.y) - radius[a] - radius[b]
                if gap < worst:
                    worst, when = gap, sa.t
    return worst, when
