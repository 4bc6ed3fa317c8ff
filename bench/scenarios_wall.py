"""Wall time of every shipped scenario, end to end as a user runs it (goal: <= 3 s each, issue 23).

    .venv/bin/python bench/scenarios_wall.py [NAME ...] [--repeat N]

Each run is `softplc scenario run NAME --out TMP` in a fresh process: imports, the simulated
run with the fleet's robots, CSV records, PNG figures and the summary. Prints simulated
seconds, wall seconds (median and best of --repeat) and the speed-up over real time; a scenario
whose median is over 3 s prints GOAL MISSED. Also checks that the runs wrote byte-identical CSV
records.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.timing import load_average, run_softplc  # noqa: E402
from softplc.scenarios.spec import builtin_scenarios  # noqa: E402

GOAL_S = 3.0


def run_once(name: str, out: Path) -> tuple[float, float, dict]:
    """Wall seconds, CPU seconds (user + system of the process) and the summary of one run."""
    run = run_softplc("scenario", "run", name, "--out", str(out), "--json")
    return run.wall, run.cpu, json.loads(run.done.stdout)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="scenario names (default: all shipped)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per scenario (the median wall time counts; default 3)")
    args = parser.parse_args()
    names = args.names or [path.stem for path in builtin_scenarios()]
    print(f"load average at start: {load_average()}")
    print(f"{'scenario':<22} {'sim s':>8} {'median s':>8} {'best s':>7} {'CPU s':>6} {'x real time':>11}  records identical")
    missed = 0
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            walls, cpus, outs = [], [], []
            for index in range(max(1, args.repeat)):
                out = Path(tmp) / f"{name}-{index}"
                wall, cpu, summary = run_once(name, out)
                walls.append(wall)
                cpus.append(cpu)
                outs.append(out)
            identical = all(
                (outs[0] / f"{kind}_{name}.csv").read_bytes() == (other / f"{kind}_{name}.csv").read_bytes()
                for other in outs[1:] for kind in ("XY", "LEV", "TSK"))
            best, median = min(walls), statistics.median(walls)
            sim = summary["sim_duration_s"]
            flag = "" if median <= GOAL_S else f"   GOAL MISSED (> {GOAL_S:g} s)"
            missed += bool(flag)
            same = ("yes" if identical else "NO") if len(outs) > 1 else "(one run)"
            print(f"{name:<22} {sim:8.1f} {median:8.2f} {best:7.2f} {statistics.median(cpus):6.2f} {sim / median:11.0f}  {same}{flag}")
    print(f"load average at end: {load_average()}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
