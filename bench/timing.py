"""Timing a command in a child process: wall seconds and the CPU seconds it (and its children) used.

Wall far above CPU means the process waited for the CPU (a busy machine), not that it worked
longer; the wall-time benchmarks print both so the two can be told apart.
"""

from __future__ import annotations

import compileall
import functools
import os
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


@dataclass
class TimedRun:
    wall: float  # seconds
    cpu: float  # user + system seconds of the child and the children it waited for
    done: subprocess.CompletedProcess[str]


@functools.cache  # once per benchmark process
def fresh_bytecode() -> None:
    """Compile the modules changed since their last compile, as scripts/bootstrap.sh does.

    Where PYTHONDONTWRITEBYTECODE is set (as on this machine), Python never saves bytecode, so a
    module edited since the bootstrap is compiled again by every run: 0.75 s more per simulated
    run with five edited modules (3.35 s instead of 2.59 s). A timing must not include that.
    """
    for folder in ("softplc", "programs", "robots"):
        compileall.compile_dir(REPO / folder, quiet=1, workers=0)


def run_softplc(*args: str) -> TimedRun:
    """`python -m softplc.app.cli ARGS` from the repository, output captured; exits on failure."""
    fresh_bytecode()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "softplc.app.cli", *args], capture_output=True, text=True, cwd=REPO,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    wall = time.monotonic() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"softplc {' '.join(args)} failed (exit {done.returncode}):\n{done.stderr}")
    return TimedRun(wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), done)


def load_average() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())
