"""Online change: the 10 ms task's start latency and missed cycles while programs.apply swaps its program.

Runs the default plant (tagdb.yaml, with its servers and robots, on free ports) plus a 10 ms task
`bench` (priority 0) whose program lives in its own module, on the real clock. After a warm-up it
applies --changes online changes one after the other (each edits the bench program's module, so
the 10 ms task's own program is checked, set up and swapped, as `softplc apply` would), and
compares the cycles whose release falls while a change is under way (from the command's call to
one cycle after its answer) with the baseline: a window as long as the previous change took,
just before each change, without one — so both see the same load of a shared machine.

Goal (issue 17): online change causes 0 missed cycles and <= 1 ms extra start latency (p99 during
the changes minus p99 of the baseline). On a shared machine the baseline misses cycles too: an
independent process (bench/stall_probe.py, waking every 1 ms) runs beside it, and a missed cycle
during which the probe was stalled too (> 5 ms late) is the machine's, not the change's; both
counts are printed, and the goal counts the others.

    .venv/bin/python bench/online_change.py                       # 40 changes
    .venv/bin/python bench/online_change.py --changes 10 --no-adapters
    .venv/bin/python bench/online_change.py --check-switch-interval 0.005    # Python's default GIL hand-over
    .venv/bin/python bench/online_change.py --no-gate       # the check does not step aside (softplc/engine/scan_gate.py)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from array import array
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc.app.adapters import build_adapters  # noqa: E402
from softplc.app.cli import build_parser  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402
from softplc.config import load_config  # noqa: E402
from softplc.core.clock import RealClock  # noqa: E402
from softplc.core.roles import Role  # noqa: E402
from softplc.core.tagdb import Origin  # noqa: E402
from softplc.engine.online_change import change as online_change  # noqa: E402
from softplc.util import realtime  # noqa: E402

GOAL_EXTRA_P99_MS = 1.0
WARMUP_S = 2.0
ENGINEER = Origin("bench", "bench", role=Role.ENGINEER)

PROGRAM = '''
from softplc import TON, InOut, Input, Program

VERSION = {version}


class BenchProgram(Program):
    """A small, typical scan (reads plant tags, keeps a timer and a counter): the program being changed."""

    count = InOut("bench counter")
    level1 = Input("t01 input buffer level")
    level2 = Input("t02 input buffer level")

    def setup(self):
        self.timer = TON(self.clock)
        self.scans = 0

    def scan(self):
        self.scans += 1
        self.timer(IN=self.level1 >= 0, PT=1.0)
        self.count = (self.count + VERSION) % 2**32
'''


def make_plant(folder: Path) -> Path:
    """The default plant plus the bench task, in `folder` (robots/, programs/ and hmi/ linked from the repository)."""
    data = yaml.safe_load((REPO / "tagdb.yaml").read_text())
    data.setdefault("tags", {})["bench_count"] = {"type": "uint32", "group": "Bench"}
    data["tasks"]["bench"] = {
        "interval": "10ms", "priority": 0,
        "programs": [{"name": "bench", "program": "bench_program.py:BenchProgram",
                      "bind": {"count": "bench_count", "level1": "t01_iBL", "level2": "t02_iBL"}}],
    }
    for name in ("robots", "programs", "hmi"):  # hmi: the views the plant declares
        (folder / name).symlink_to(REPO / name)
    (folder / "bench_program.py").write_text(PROGRAM.format(version=1))
    config = folder / "tagdb.yaml"
    config.write_text(yaml.safe_dump(data, sort_keys=False))
    return config


def figures(samples: np.ndarray) -> tuple[float, float, float]:
    if not len(samples):
        return (float("nan"),) * 3  # type: ignore[return-value]
    p50, p99 = np.percentile(samples, [50, 99])
    return float(p50), float(p99), float(samples.max())


async def measure(config_path: Path, changes: int, gap_s: float, adapters_on: bool, state_dir: Path) -> dict:
    config = load_config(config_path)
    runtime = Runtime(config, RealClock(), state_dir=state_dir)
    if adapters_on:
        args = build_parser().parse_args(["run", str(config_path), "--modbus-port", "0", "--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--hmi-port", "0"])
        for adapter in build_adapters(config, args):
            runtime.add_adapter(adapter)
    task = next(t for t in runtime.tasks if t.name == "bench")
    starts, latencies, ends, missed = array("d"), array("d"), array("d"), array("d")
    measuring = False
    record = task.record

    def recording(release: float, start: float, end: float) -> None:
        before = task.stats.overruns
        record(release, start, end)
        if measuring:
            starts.append(release)
            latencies.append(start - release)
            ends.append(end)
            missed.append(task.stats.overruns - before)

    task.record = recording  # type: ignore[method-assign]
    windows: list[tuple[float, float]] = []  # while a change is under way
    controls: list[tuple[float, float]] = []  # as long, just before it, without a change
    apply_s: list[float] = []
    swap_s: list[float] = []
    swap = runtime.online_change._swap

    def timed_swap(prepared: object) -> dict:
        started = time.perf_counter()
        try:
            return swap(prepared)  # type: ignore[arg-type]
        finally:
            swap_s.append(time.perf_counter() - started)

    runtime.online_change._swap = timed_swap  # type: ignore[method-assign]
    module = config_path.parent / "bench_program.py"
    await runtime.start()
    try:
        await runtime.clock.sleep(WARMUP_S)
        probe = subprocess.Popen([sys.executable, str(REPO / "bench" / "stall_probe.py"), str(changes * (gap_s + 5) + 5)],
                                 stdout=subprocess.PIPE, text=True)
        offset = runtime.clock.monotonic() - runtime.clock.now()  # clock time → the probe's monotonic time
        measuring = True
        control = 0.5
        for index in range(changes):
            began = runtime.clock.now()
            await runtime.clock.sleep(control)
            controls.append((began, runtime.clock.now()))
            module.write_text(PROGRAM.format(version=2 + index % 2))
            began = runtime.clock.now()
            result = await runtime.commands.call("programs.apply", {}, ENGINEER)
            ended = runtime.clock.now()
            assert result["applied"], result
            windows.append((began, ended + task.interval))
            apply_s.append(ended - began)
            control = ended + task.interval - began
            await runtime.clock.sleep(gap_s)
        measuring = False
        probe.terminate()
        stalls = [time for time, _ in json.loads((await asyncio.to_thread(probe.communicate, timeout=30))[0] or '{"stalls": []}')["stalls"]]
    finally:
        await runtime.stop()
    release, latency, lost = np.frombuffer(starts), np.frombuffer(latencies) * 1e3, np.frombuffer(missed)
    end = np.frombuffer(ends)
    stalled = np.array([any(r + offset - 0.005 <= t <= e + offset + 0.05 for t in stalls) for r, e in zip(release, end)], dtype=bool)

    def within(spans: list[tuple[float, float]]) -> np.ndarray:
        mask = np.zeros(len(release), dtype=bool)
        for began, ended in spans:
            mask |= (release >= began) & (release < ended)
        return mask

    during, base = within(windows), within(controls)

    def window(mask: np.ndarray) -> tuple[int, int, int, tuple[float, float, float]]:
        return int(mask.sum()), int(lost[mask].sum()), int(lost[mask & stalled].sum()), figures(latency[mask])

    return {
        "adapters": [adapter.describe() for adapter in runtime.adapters],
        "baseline": window(base),
        "during": window(during),
        "stalls": len(stalls),
        "apply_ms": (1e3 * float(np.mean(apply_s)), 1e3 * max(apply_s)) if apply_s else (0.0, 0.0),
        "swap_ms": (1e3 * float(np.median(swap_s)), 1e3 * max(swap_s)) if swap_s else (0.0, 0.0),
        "version": runtime.program("bench").version,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--changes", type=int, default=40, help="online changes applied (default 40)")
    parser.add_argument("--gap", type=float, default=0.25, help="seconds between two changes (default 0.25)")
    parser.add_argument("--no-adapters", action="store_true", help="scan only: start no server or fleet")
    parser.add_argument("--check-switch-interval", type=float, metavar="S",
                        help=f"GIL switch interval the runtime shortens to, the check's included (default {realtime.SWITCH_INTERVAL})")
    parser.add_argument("--no-gate", action="store_true", help="the check does not step aside around releases (for comparison)")
    args = parser.parse_args(argv)
    online_change.USE_SCAN_GATE = not args.no_gate
    if args.check_switch_interval is not None:
        realtime.SWITCH_INTERVAL = args.check_switch_interval
    with open("/proc/loadavg") as file:
        load = " ".join(file.read().split()[:3])
    print(f"online change: default plant + 10 ms bench task, {args.changes} changes "
          f"{args.gap:g} s apart, check switch interval {realtime.SWITCH_INTERVAL * 1e3:g} ms, "
          f"scan gate {'on' if online_change.USE_SCAN_GATE else 'off'}; "
          f"Python {platform.python_version()}, {os.cpu_count()} CPUs, load average {load}")
    folder = Path(tempfile.mkdtemp(prefix="softplc-online-change-"))
    try:
        config = make_plant(folder)
        with asyncio.Runner() as runner:
            result = runner.run(measure(config, args.changes, args.gap, not args.no_adapters, folder / "state"))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    print(f"adapters running: {'; '.join(result['adapters']) or 'none'}")
    print(f"changes applied: {result['version'] - 1}; programs.apply took {result['apply_ms'][0]:.0f} ms mean, "
          f"{result['apply_ms'][1]:.0f} ms max (checked off the scan path); the swap at the scan boundary "
          f"{result['swap_ms'][0]:.3f} ms median, {result['swap_ms'][1]:.3f} ms max")
    print()
    print(f"stall probe: {result['stalls']} stalls of the whole machine (> 5 ms) during the measurement")
    print()
    print("| 10 ms task | cycles | missed cycles (machine stalled too) | start latency ms p50 / p99 / max |")
    print("|---|---|---|---|")
    for name in ("baseline", "during"):
        cycles, lost, witnessed, (p50, p99, worst) = result[name]
        label = "baseline: just before each change, as long" if name == "baseline" else "while a change is checked and swapped"
        print(f"| {label} | {cycles} | {lost} ({witnessed}) | {p50:.3f} / {p99:.3f} / {worst:.3f} |")
    extra = result["during"][3][1] - result["baseline"][3][1]
    print()
    lost = result["during"][1] - result["during"][2]
    if lost or extra > GOAL_EXTRA_P99_MS:
        print(f"!!! GOAL MISSED !!! during the changes: {lost} missed cycles without a machine stall (goal 0), p99 start "
              f"latency {extra:+.3f} ms over the baseline (goal <= {GOAL_EXTRA_P99_MS} ms)")
        return 1
    print(f"goal met: 0 missed cycles (but the machine's), p99 start latency {extra:+.3f} ms over the baseline "
          f"(goal <= {GOAL_EXTRA_P99_MS} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
