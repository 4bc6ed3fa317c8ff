"""Wall time of `softplc run --sim --duration 600` on the default plant, everything on (goal: <= 3 s).

    .venv/bin/python bench/sim_wall.py [--duration S] [--repeat N] [--config FILE] [--fresh]
    .venv/bin/python bench/sim_wall.py --no-servers      # the same without OPC UA, Modbus, HMI, history, audit

Everything that runs under --sim is on unless asked otherwise: OPC UA, Modbus, the HMI with its
metrics, the historian, the alarms and their journal, the audit trail, the robots. Each run is a
fresh process, as a user runs it: imports, the adapters' start, ten simulated minutes, the stop
and the exit statistics. A first run, not counted, makes what a first start on a machine makes
(the state directory, the OPC UA server certificate, the cached standard OPC UA nodes) and is
printed apart; the counted runs then use that state directory, as a user's second run does
(--fresh: a new state directory each run, i.e. a new certificate every time). Prints the load
average, wall and CPU seconds of every run, their median, and GOAL MISSED when the median wall
time is over 3 s (200 x real time for 600 simulated seconds). Wall far above CPU means the
process waited for the CPU (a busy machine), not that it worked longer.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.timing import REPO, load_average, run_softplc  # noqa: E402

GOAL_S = 3.0
OFF = ("--no-servers", "--no-hmi", "--no-history", "--no-audit")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=REPO / "tagdb.yaml", help="plant file (default tagdb.yaml)")
    parser.add_argument("--duration", type=float, default=600.0, help="simulated seconds per run (default 600)")
    parser.add_argument("--repeat", type=int, default=5, help="counted runs (default 5; the median counts for the goal)")
    parser.add_argument("--fresh", action="store_true", help="a new state directory for every run")
    parser.add_argument("--no-servers", action="store_true", help=f"run with {' '.join(OFF)} (no goal: a comparison)")
    args = parser.parse_args()
    extra = OFF if args.no_servers else ()
    print(f"load average at start: {load_average()}")
    print(f"{'run':>5} {'wall s':>7} {'CPU s':>6}")
    walls = []
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(max(1, args.repeat) + 1):
            state = Path(tmp) / (f"state-{index}" if args.fresh else "state")
            run = run_softplc("run", str(args.config), "--sim", "--duration", str(args.duration), "--state-dir", str(state), *extra)
            label = "first" if index == 0 else str(index)
            print(f"{label:>5} {run.wall:7.2f} {run.cpu:6.2f}" + ("   (not counted: makes the state directory and caches)" if index == 0 else ""))
            if index:
                walls.append(run.wall)
    median = statistics.median(walls)
    flag = "" if median <= GOAL_S or args.no_servers else f"   GOAL MISSED (> {GOAL_S:g} s)"
    print(f"median {median:.2f} s (best {min(walls):.2f}, worst {max(walls):.2f}) for {args.duration:g} simulated seconds: "
          f"{args.duration / median:.0f} x real time{flag}")
    print(f"load average at end: {load_average()}")
    return 1 if flag else 0


if __name__ == "__main__":
    sys.exit(main())
