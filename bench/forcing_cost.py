"""Forcing cost per scan with 1,000 forced tags (issue 17, item 1): CPU time of a cycle with and without forces.

A plant of 3,000 float64 tags. One task's program reads and writes 1,000 of them every scan (each
value changes, so every output is committed); 2,000 others are not bound. The cycles are run
directly (`ScanEngine.cycle`: apply the journal, the image, the program, the commit) with thread
CPU time around each, so the figures do not depend on the machine's load. Cases:

- none: nothing forced (the baseline);
- outputs: the 1,000 tags the program writes are forced — it reads the forced values, its writes
  to them are dropped at the commit (the CODESYS semantics, softplc/core/forcing.py);
- elsewhere: 1,000 tags no program binds are forced (the cost of the forces themselves);

and, once, what setting and releasing 1,000 forces costs at the cycle boundary that applies them.

    .venv/bin/python bench/forcing_cost.py                 # 2,000 cycles per case
    .venv/bin/python bench/forcing_cost.py --cycles 5000
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.timing import load_average  # noqa: E402
from softplc import InOut, Program  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402
from softplc.config import parse_config  # noqa: E402
from softplc.core.clock import SimClock  # noqa: E402
from softplc.core.roles import Role  # noqa: E402
from softplc.core.tagdb import Origin  # noqa: E402

BOUND = 1000
OTHER = 2000
ENGINEER = Origin("bench", "engineer", role=Role.ENGINEER)


class Mover(Program):
    """Adds 1 to each of its values every scan: every output changes."""

    values = InOut("the values")

    def scan(self) -> None:
        self.values = [value + 1.0 for value in self.values]


def plant() -> str:
    bound = [f"b{index:04d}" for index in range(BOUND)]
    other = [f"o{index:04d}" for index in range(OTHER)]
    declared = "\n".join(f"  {name}: {{type: float64}}" for name in bound + other)
    return f"""
version: 1
plant: {{name: forcing-cost}}
tags:
{declared}
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: mover, program: "{Path(__file__).resolve()}:Mover", bind: {{values: [{", ".join(bound)}]}}}}
"""


def per_cycle(runtime: Runtime, cycles: int) -> list[float]:
    """CPU µs of each of `cycles` cycles of the task, run directly."""
    engine, task = runtime.engine, runtime.tasks[0]
    costs = []
    for _ in range(cycles):
        started = time.thread_time()
        engine.cycle(task, 0.0)
        costs.append((time.thread_time() - started) * 1e6)
    return costs


def force(runtime: Runtime, names: list[str]) -> float:
    """Force the tags; CPU µs of the boundary that applies the forces."""
    for name in names:
        runtime.db.force(name, 7.0, ENGINEER)
    started = time.thread_time()
    runtime.db.apply_journal()
    return (time.thread_time() - started) * 1e6


def release(runtime: Runtime, names: list[str]) -> float:
    for name in names:
        runtime.db.unforce(name, restore=True)
    started = time.thread_time()
    runtime.db.apply_journal()
    return (time.thread_time() - started) * 1e6


def summary(costs: list[float]) -> str:
    ordered = sorted(costs)
    return f"median {statistics.median(ordered):7.1f} µs, p99 {ordered[int(len(ordered) * 0.99)]:7.1f} µs"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2000, help="cycles per case (default 2000)")
    args = parser.parse_args()
    print(f"# {BOUND} tags read and written by a program every scan, {OTHER} others; {args.cycles} cycles per case; "
          f"load average {load_average()} (CPU time: the load does not count)")
    config = parse_config(plant(), REPO / "bench" / "forcing.yaml")
    runtime = Runtime(config, SimClock(), retain=False)
    runtime.engine.start_programs()
    bound = [f"b{index:04d}" for index in range(BOUND)]
    other = [f"o{index:04d}" for index in range(BOUND)]
    per_cycle(runtime, 200)  # warm-up
    results = {}
    results["none"] = per_cycle(runtime, args.cycles)
    set_cost = force(runtime, bound)
    results["outputs"] = per_cycle(runtime, args.cycles)
    assert runtime.db.value("b0000") == 7.0 and len(runtime.db.forces) == BOUND  # the program's writes were dropped
    release_cost = release(runtime, bound)
    force(runtime, other)
    results["elsewhere"] = per_cycle(runtime, args.cycles)
    release(runtime, other)
    results["none, again"] = per_cycle(runtime, args.cycles)
    baseline = statistics.median(results["none"] + results["none, again"])
    for case, costs in results.items():
        extra = statistics.median(costs) - baseline
        print(f"{case:12s} {summary(costs)}  ({extra:+.1f} µs against nothing forced)")
    print(f"forcing 1,000 tags: {set_cost:.0f} µs at the boundary that applies them; releasing them (restore): {release_cost:.0f} µs")
    print(f"# load average after: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
