"""Fleet scaling: how many simulated robots one runtime drives at a 100 ms cycle, in real time.

For each fleet size N, a runtime on the real clock (with a 100 ms plant task, like the default
plant) drives N simulated robots on a 100 x 60 m warehouse floor; each robot shuttles along
its own 2 m lane (lanes 1.5 m apart, so every robot has neighbours within its 3 m sensing
range), re-planning with A* at every end of its lane. After a warm-up (the first plans of all
robots), it measures for --seconds: control-loop overruns (a cycle that ended after the next
release), the plant task's overruns, the robots' step time, the wake-up lateness of the
robots' cycles, and the CPU used by the process.

Goal (issue 23, was 100 in issue 4): 1,000 robots at 100 ms with zero overruns on this 2-core
machine; GOAL MISSED when the largest fleet without overruns is smaller.

    .venv/bin/python bench/fleet_scale.py                       # N = 1 ... 1,000, 15 s each
    .venv/bin/python bench/fleet_scale.py --robots 1000          # the goal alone
    .venv/bin/python bench/fleet_scale.py --robots 100 200 --seconds 30
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc.adapters.fleet.adapter import FleetAdapter  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402
from softplc.config import load_config  # noqa: E402
from softplc.core.clock import RealClock  # noqa: E402
from softplc.robotics.gridmap import OccupancyGrid  # noqa: E402
from softplc.robotics.robots import load_robots  # noqa: E402

GOAL_ROBOTS = 1000
WIDTH, HEIGHT, LANE, SPACING = 100.0, 60.0, 2.0, 1.5

PLANT = """\
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
tasks:
  plant: {interval: 100ms}
# No Modbus server runs here; 1,000 robots' tags would not fit its register tables anyway.
servers:
  modbus: {enabled: false}
"""

ROBOT = """\
  - {{id: {id}, length_mm: 255, width_mm: 255, height_mm: 400, load_capacity: 20, max_linear_speed: 0.2,
     max_angular_speed: 0.4, hardware: [laser_range_finder, two_wheel_drive], start: {{x: {x}, y: {y}, heading: 1.5708}}}}
"""


def warehouse() -> OccupancyGrid:
    resolution = 0.1
    occupied = np.zeros((int(HEIGHT / resolution), int(WIDTH / resolution)), dtype=bool)
    occupied[:2, :] = occupied[-2:, :] = occupied[:, :2] = occupied[:, -2:] = True
    return OccupancyGrid(occupied, resolution, name="warehouse")


def lanes(count: int) -> list[tuple[float, float, float]]:
    """(x, y_low, y_high) of each robot's lane."""
    result = []
    x = 1.5
    while len(result) < count:
        y = 1.5
        while y + LANE < HEIGHT - 1.5 and len(result) < count:
            result.append((x, y, y + LANE))
            y += LANE + SPACING
        x += SPACING
        if x > WIDTH - 1.5:
            raise SystemExit(f"{count} robots do not fit on the floor")
    return result


async def shuttle(runtime: Runtime, ids: list[str], slots: list[tuple[float, float, float]]) -> None:
    """Send every robot that is done to the other end of its lane (a simple 'sequencer')."""
    db = runtime.db
    while True:
        for robot_id, (x, low, high) in zip(ids, slots):
            if not db.value(f"{robot_id}_status") and db.value(f"{robot_id}_navstate") in ("idle", "arrived", "failed"):
                target = high if abs(db.value(f"{robot_id}_ypos") - low) < 1.0 else low
                db.submit([(f"{robot_id}_xgoal", x), (f"{robot_id}_ygoal", target), (f"{robot_id}_status", True)], "bench")
        await runtime.clock.sleep(0.5)


async def measure(count: int, seconds: float, warmup: float) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as directory:
        folder = Path(directory)
        slots = lanes(count)
        ids = [f"r{index + 1:03d}" for index in range(count)]
        (folder / "robots.yaml").write_text("robots:\n" + "".join(ROBOT.format(id=i, x=x, y=low) for i, (x, low, _) in zip(ids, slots)))
        (folder / "tagdb.yaml").write_text(PLANT)
        config = load_config(folder / "tagdb.yaml")
        runtime = Runtime(config, RealClock(), state_dir=folder / "state")
        fleet = FleetAdapter(load_robots(folder / "robots.yaml"), warehouse())
        runtime.add_adapter(fleet)
        await runtime.start()
        commander = asyncio.ensure_future(shuttle(runtime, ids, slots))
        try:
            await asyncio.sleep(warmup)
            plant = runtime.tasks[0].stats
            before = {robot_id: (s.cycles, s.overruns, s.step_total, s.plans) for robot_id, s in fleet.stats().items()}
            plant_before = (plant.cycles, plant.overruns)
            cpu, wall = time.process_time(), time.perf_counter()
            maxima = {robot_id: 0.0 for robot_id in ids}
            for stats in fleet.stats().values():
                stats.step_max = 0.0
            await asyncio.sleep(seconds)
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            after = fleet.stats()
            cycles = sum(after[r].cycles - before[r][0] for r in ids)
            overruns = sum(after[r].overruns - before[r][1] for r in ids)
            step = sum(after[r].step_total - before[r][2] for r in ids)
            plans = sum(after[r].plans - before[r][3] for r in ids)
            maxima = {r: after[r].step_max for r in ids}
            moving = sum(1 for r in ids if runtime.db.value(f"{r}_navstate") == "moving")
            return {
                "robots": count, "cycles": cycles, "expected": count * seconds / 0.1, "overruns": overruns,
                "plant_overruns": plant.overruns - plant_before[1], "step_us": 1e6 * step / max(cycles, 1),
                "step_max_ms": 1e3 * max(maxima.values()), "cpu": cpu / wall, "plans": plans, "moving": moving,
                "ms_per_cycle": 1e3 * step / max(cycles, 1) * count,
            }
        finally:
            commander.cancel()
            await runtime.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 10, 50, 100, 200, 300, 500, 750, 1000])
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--warmup", type=float, default=5.0)
    args = parser.parse_args()
    print(f"fleet scaling: {args.seconds:g} s per size after {args.warmup:g} s warm-up, 100 ms robot cycle, real clock")
    print(f"{'robots':>6} {'cycles':>8} {'of':>8} {'overruns':>8} {'plant ovr':>9} {'step us':>8} {'step max ms':>11} "
          f"{'ms/100ms':>8} {'CPU':>5} {'plans':>6} {'moving':>6}")
    best = 0
    for count in args.robots:
        r = asyncio.run(measure(count, args.seconds, args.warmup))
        print(f"{r['robots']:>6} {r['cycles']:>8} {r['expected']:>8.0f} {r['overruns']:>8} {r['plant_overruns']:>9} "
              f"{r['step_us']:>8.1f} {r['step_max_ms']:>11.2f} {r['ms_per_cycle']:>8.1f} {r['cpu']:>5.0%} {r['plans']:>6} {r['moving']:>6}",
              flush=True)
        if r["overruns"] == 0 and r["plant_overruns"] == 0:
            best = max(best, count)
    verdict = "goal met" if best >= GOAL_ROBOTS else "GOAL MISSED"
    print(f"largest fleet with zero overruns: {best} robots (goal >= {GOAL_ROBOTS}): {verdict}")


if __name__ == "__main__":
    main()
