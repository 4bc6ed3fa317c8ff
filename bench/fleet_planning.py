"""A* planning time on the default factory map, and the per-cycle cost of one simulated robot.

Planning: every ordered pair of the factory map's stations and robot starts (SPEC §2, §4),
for a TurtleBot (radius 0.18 m) and the thesis's largest robot (500 x 600 mm, radius 0.39 m),
on the default 0.1 m planning grid and on a 0.05 m grid. Goal: the median plan on the default
grid takes under 20 ms. Plans may take longer (a long way round the partitions), so they never
run on the event loop: in real time the runtime sends them to a worker process
(softplc/robotics/planning.py).

Event-loop stall: on the real clock, every pair is planned back to back, once in an executor
thread (clock.run_blocking: the GIL is shared with the loop) and once in the planning worker
process (5 rounds each), while a 1 ms ticker on the event loop records how late it wakes up
(and once with no planning at all). Goal: with the worker process the ticker's p99 stays within
0.5 ms of the idle loop's (its maximum shows the machine's own stalls). The ticker waits as the
scan engine does (RealClock: a timer, then a short spin), since asyncio's timers alone are up to
1 ms late whenever I/O wakes the loop in between (epoll's millisecond timeouts).

One robot: a TurtleBot driven around all four stations by the fleet adapter on the simulated
clock; the wall time of each control cycle (read goal tags, traffic check, pure pursuit,
kinematics, publish) as measured by the control loop itself. Goal: far below 1 ms, i.e.
hundreds of robots fit in one 100 ms cycle.

    .venv/bin/python bench/fleet_planning.py
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc.adapters.fleet.adapter import FleetAdapter  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402
from softplc.config import load_config  # noqa: E402
from softplc.core.clock import RealClock, SimClock  # noqa: E402
from softplc.robotics.driver import PlanRequest  # noqa: E402
from softplc.robotics.floor import Floor  # noqa: E402
from softplc.robotics.gridmap import load_map  # noqa: E402
from softplc.robotics.planning import ClockPlanning, ProcessPlanning  # noqa: E402
from softplc.robotics.robots import load_robots  # noqa: E402

FACTORY = REPO / "robots" / "maps" / "factory.yaml"
POINTS = [(3.5, 7.5), (1.8, 2.5), (18.5, 7.5), (20.1, 2.4), (7.925, 5.925), (7.925, 2.925), (7.925, 4.525)]
PLAN_GOAL_MS = 20.0
STEP_GOAL_US = 1000.0


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100 * (len(ordered) - 1))))]


ROUNDS = 5
STALL_GOAL_MS = 0.5  # ms of p99 lateness planning may add


async def idle_ticker(seconds: float = 2.0) -> tuple[float, float]:
    """Worst and p99 lateness (ms) of a 1 ms ticker on an otherwise idle loop."""
    clock = RealClock()
    late: list[float] = []
    end = clock.now() + seconds
    while clock.now() < end:
        target = clock.now() + 0.001
        await clock.sleep_until(target)  # as the scan engine waits: asyncio's timers alone are ~1 ms coarse
        late.append((clock.now() - target) * 1000)
    return max(late), percentile(late, 99)


async def loop_stall(in_worker: bool) -> tuple[float, float, int]:
    """Worst and p99 ticker lateness (ms) while planning every pair off the loop; plans made."""
    clock = RealClock()
    planner = Floor(load_map(FACTORY)).planner(0.39)
    worker = ProcessPlanning([planner], ClockPlanning(clock)) if in_worker else None
    if worker is not None:
        await worker.start()
    late: list[float] = []
    done = asyncio.Event()

    async def ticker() -> None:
        while not done.is_set():
            target = clock.now() + 0.001
            await clock.sleep_until(target)
            late.append((clock.now() - target) * 1000)

    ticking = asyncio.ensure_future(ticker())
    plans = 0
    for a, b in [(a, b) for a in POINTS for b in POINTS if a != b] * ROUNDS:
        if worker is not None:
            plan = await worker.run(PlanRequest(plans, planner, a, b))
        else:
            plan = await clock.run_blocking(planner.plan, a, b)
        assert plan.ok
        plans += 1
    done.set()
    await ticking
    if worker is not None:
        await worker.stop()
    return max(late), percentile(late, 99), plans


def planning() -> bool:
    grid = load_map(FACTORY)
    ok = True
    print(f"A* on the factory map ({grid.size_m[0]:.2f} x {grid.size_m[1]:.2f} m), {len(POINTS) * (len(POINTS) - 1)} station pairs")
    print(f"{'grid':>6} {'radius':>6} {'cells':>7} {'build ms':>8} {'median ms':>9} {'p90 ms':>7} {'max ms':>7} {'expanded max':>12}")
    for resolution in (0.1, 0.05):
        for radius in (0.18, 0.39):
            began = time.perf_counter()
            planner = Floor(grid, planning_resolution=resolution).planner(radius)
            build = time.perf_counter() - began
            times, expanded = [], []
            for _ in range(3):  # repeat: the median is over 3 x 42 plans
                for a in POINTS:
                    for b in POINTS:
                        if a != b:
                            plan = planner.plan(a, b)
                            assert plan.ok, (a, b, plan.reason)
                            times.append(plan.seconds * 1000)
                            expanded.append(plan.expanded)
            cells = planner.grid.width * planner.grid.height
            print(f"{resolution:>6} {radius:>6} {cells:>7} {build * 1000:>8.1f} {statistics.median(times):>9.2f} "
                  f"{percentile(times, 90):>7.2f} {max(times):>7.2f} {max(expanded):>12}")
            if resolution == 0.1 and statistics.median(times) > PLAN_GOAL_MS:
                ok = False
    return ok


async def one_robot() -> list[float]:
    with tempfile.TemporaryDirectory() as directory:
        folder = Path(directory)
        text = (REPO / "tagdb.yaml").read_text()
        (folder / "tagdb.yaml").write_text(text)
        (folder / "robots").mkdir()
        (folder / "robots" / "robots.yaml").write_text((REPO / "robots" / "robots.yaml").read_text())
        # What the plant names beside its robots file: the tasks, the maps, the HMI's views.
        for shared in ("robots/tasks.yaml", "robots/maps", "robots/roadmap.yaml", "hmi"):
            if (REPO / shared).exists():
                (folder / shared).symlink_to(REPO / shared)
        config = load_config(folder / "tagdb.yaml")
        runtime = Runtime(config, SimClock(), state_dir=folder / "state")
        fleet = FleetAdapter(load_robots(folder / "robots" / "robots.yaml"), load_map(FACTORY))
        runtime.add_adapter(fleet)
        await runtime.start()
        steps: list[float] = []
        try:
            loop = fleet.loops["r01"]
            for x, y in [(3.5, 7.5), (1.8, 2.5), (18.5, 7.5), (20.1, 2.4)] * 2:
                runtime.db.submit([("r01_xgoal", x), ("r01_ygoal", y), ("r01_status", True)], "bench")
                await runtime.clock.sleep(0.5)
                while runtime.db.value("r01_status"):
                    before = loop.stats.step_total
                    await runtime.clock.sleep(0.1)
                    steps.append((loop.stats.step_total - before) * 1e6)
        finally:
            await runtime.stop()
        return steps


def main() -> None:
    ok = planning()
    print()
    idle_max, idle_p99 = asyncio.run(idle_ticker())
    print(f"event loop with no planning: 1 ms ticker late by p99 {idle_p99:.2f} ms, max {idle_max:.2f} ms")
    worker_ok = True
    for in_worker, where in ((False, "in an executor thread (clock.run_blocking)"), (True, "in the planning worker process")):
        stall, stall_p99, plans = asyncio.run(loop_stall(in_worker))
        print(f"event loop while {plans} plans ran {where}: 1 ms ticker late by p99 {stall_p99:.2f} ms, max {stall:.2f} ms")
        if in_worker and stall_p99 > idle_p99 + STALL_GOAL_MS:
            print(f"  !!! GOAL MISSED !!! ticker p99 {stall_p99:.2f} ms while planning in the worker (goal <= idle {idle_p99:.2f} + {STALL_GOAL_MS:g} ms)")
            worker_ok = False
    steps = asyncio.run(one_robot())
    print(f"\none robot, {len(steps)} control cycles while driving (3 robots on the floor, simulated clock):")
    print(f"  step wall time: median {statistics.median(steps):.1f} us, p99 {percentile(steps, 99):.1f} us, max {max(steps):.1f} us "
          f"(max includes cycles that received a new plan)")
    print(f"A* median on the default 0.1 m grid within {PLAN_GOAL_MS:g} ms: {'goal met' if ok else 'GOAL MISSED'}")
    print(f"planning in the worker adds at most {STALL_GOAL_MS:g} ms to the loop's p99 lateness: {'goal met' if worker_ok else 'GOAL MISSED'}")
    step_ok = statistics.median(steps) < STEP_GOAL_US
    print(f"one robot's cycle under {STEP_GOAL_US:g} us: {'goal met' if step_ok else 'GOAL MISSED'}")


if __name__ == "__main__":
    main()
