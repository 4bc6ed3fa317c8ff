"""Robots' plans in a worker process on the real clock (the scan never waits for an A*)."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from conftest import REPO
from fleet_support import Plant, robot_yaml, write_plant

from softplc.core.clock import RealClock, SimClock
from softplc.robotics.driver import PlanRequest, run_plan
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.planner import Disc, Plan
from softplc.robotics.planning import ClockPlanning, ProcessPlanning

FACTORY = REPO / "robots" / "maps" / "factory.yaml"


class Recording:
    """A fallback that notes what reached it."""

    def __init__(self) -> None:
        self.requests: list[PlanRequest] = []

    async def run(self, request: PlanRequest) -> Plan:
        self.requests.append(request)
        return run_plan(request)


async def test_the_worker_plans_exactly_what_an_inline_plan_gives() -> None:
    floor = Floor(load_map(FACTORY))
    known, unknown = floor.planner(0.18), floor.planner(0.39)
    fallback = Recording()
    planning = ProcessPlanning([known], fallback)
    await planning.start()
    try:
        requests = [
            PlanRequest(1, known, (7.925, 5.925), (18.5, 7.5)),
            PlanRequest(2, known, (7.925, 5.925), (3.5, 7.5), [Disc(5.5, 6.5, 0.4)]),
            PlanRequest(3, known, (7.925, 5.925), (12.5, 4.3)),  # inside the rack island: no plan
        ]
        for request in requests:
            planned, inline = await planning.run(request), run_plan(request)
            assert (planned.ok, planned.path, planned.reason) == (inline.ok, inline.path, inline.reason)
        assert not planned.ok  # the last one
        assert fallback.requests == []
        other = PlanRequest(4, unknown, (7.925, 5.925), (18.5, 7.5))
        assert (await planning.run(other)).ok
        assert fallback.requests == [other]  # a planner the worker does not hold runs in the fallback
    finally:
        await planning.stop()


async def test_a_worker_that_died_is_replaced(caplog: pytest.LogCaptureFixture) -> None:
    floor = Floor(load_map(FACTORY))
    planner = floor.planner(0.18)
    planning = ProcessPlanning([planner], Recording())
    await planning.start()
    try:
        first = planning.worker_pid
        assert first is not None and first != os.getpid()
        os.kill(first, signal.SIGKILL)
        requests = [PlanRequest(serial, planner, (7.925, 5.925), (18.5, 7.5)) for serial in range(3)]
        plans = await asyncio.gather(*(planning.run(request) for request in requests))  # all find it broken
        assert all(plan.ok for plan in plans)
        assert planning.worker_pid not in (None, first)
        assert sum("planning worker process" in record.message for record in caplog.records) == 1, caplog.records
    finally:
        await planning.stop()


async def test_a_fleet_on_the_real_clock_plans_in_a_worker_process(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925)])
    async with Plant(tagdb, load_map(FACTORY), RealClock()) as plant:
        assert isinstance(plant.fleet._planning, ProcessPlanning)
        plant.send("r01", 9.0, 5.925)
        await plant.run_until(lambda: plant.fleet.stats()["r01"].plans >= 1, limit=20.0)
        await plant.run_until(lambda: plant.db.value("r01_navstate") in ("moving", "arrived"), limit=5.0)
    assert plant.fleet._planning is None  # stopped with the runtime


async def test_simulated_fleets_plan_inline(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925)])
    async with Plant(tagdb, load_map(FACTORY), SimClock()) as plant:
        assert plant.fleet._planning is None
        assert all(loop.planning is not None and isinstance(loop.planning, ClockPlanning) for loop in plant.fleet.loops.values())


@pytest.mark.parametrize("delay", [0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
def test_ctrl_c_while_the_planning_worker_starts_never_hangs(tmp_path: Path, delay: float) -> None:
    # Ctrl-C reaches the whole process group. A worker that died half-way through its start
    # once left `softplc run` blocked for good writing the planners into its pipe.
    process = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "run", str(REPO / "tagdb.yaml"), "--no-servers", "--no-status",
         "--state-dir", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True, cwd=REPO,
    )
    try:
        assert process.stdout is not None
        header = process.stdout.readline()  # printed before the adapters (and the worker) start
        assert header.startswith("softplc "), header
        time.sleep(delay)  # where in the start-up the signal lands, not a wait for a result
        os.killpg(process.pid, signal.SIGINT)
        output, _ = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode in (0, 130), output
    assert "Traceback" not in output, output


def test_a_script_without_a_main_guard_gets_its_worker(tmp_path: Path) -> None:
    # The worker must not re-run the program that embeds softplc (a multiprocessing pool would).
    script = tmp_path / "embed.py"
    script.write_text(textwrap.dedent(f"""\
        import asyncio
        from softplc.robotics.floor import Floor
        from softplc.robotics.gridmap import load_map
        from softplc.robotics.driver import PlanRequest
        from softplc.robotics.planning import ClockPlanning, ProcessPlanning
        from softplc.core.clock import RealClock

        print("script body ran", flush=True)  # once, by this process only

        async def main():
            planner = Floor(load_map({str(FACTORY)!r})).planner(0.18)
            planning = ProcessPlanning([planner], ClockPlanning(RealClock()))
            await planning.start()
            plan = await planning.run(PlanRequest(1, planner, (7.925, 5.925), (18.5, 7.5)))
            print("worker", planning.worker_pid is not None, "plan", plan.ok, flush=True)
            await planning.stop()

        asyncio.run(main())
    """))
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["script body ran", "worker True plan True"], result.stdout + result.stderr
    assert "cannot start" not in result.stderr, result.stderr
