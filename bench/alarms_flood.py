"""An alarm flood of 1,000 transitions/s: every transition journaled, and the scan keeps its timing.

Goal (issue 16): the flood journals every transition and the scan keeps its timing.

A plant on the real clock with 1,000 discrete alarms on 1,000 bool tags: a 100 ms task flips
--per-scan of them every scan (100 = 1,000 transitions/s: half activations, half returns to
normal), beside a 10 ms task with a small program whose start latency is the timing measured
(its goal elsewhere: p99 <= 1 ms, max <= 5 ms). The journal is the default SQLite store. The
same plant runs once without its alarms: section as the baseline. After each run the journal
is opened as a reader and its rows counted against the transitions published.

    .venv/bin/python bench/alarms_flood.py                     # 30 s flood + 30 s baseline
    .venv/bin/python bench/alarms_flood.py --seconds 10 --per-scan 200 --opcua
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc import InOut, Param, Program  # noqa: E402
from softplc.app.adapters import build_adapters  # noqa: E402
from softplc.core.clock import RealClock  # noqa: E402
from softplc.config import load_config  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402

WARMUP_S = 2.0


class Flooder(Program):
    """Flips `per_scan` of its flags every scan, round robin."""

    flags = InOut("the flags")
    per_scan = Param(100, "flags flipped per scan")

    def setup(self) -> None:
        self.cursor = 0

    def scan(self) -> None:
        flags = self.flags
        for _ in range(self.per_scan):
            flags[self.cursor] = not flags[self.cursor]
            self.cursor = (self.cursor + 1) % len(flags)


class Ticker(Program):
    """The measured 10 ms task's small scan."""

    count = InOut("scan counter")

    def scan(self) -> None:
        self.count = (self.count + 1) % 2**32


def plant(count: int, per_scan: int, alarms: bool, opcua: bool) -> str:
    flags = ", ".join(f"f{index:04d}_x" for index in range(count))
    here = Path(__file__).resolve()
    text = f"""
version: 1
templates:
  flag:
    instances: [{", ".join(f"f{index:04d}" for index in range(count))}]
    tags:
      x: {{type: bool}}
tags:
  ticks: {{type: uint32}}
tasks:
  fast:
    interval: 10ms
    priority: 0
    programs:
      - {{name: ticker, program: "{here}:Ticker", bind: {{count: ticks}}}}
  flood:
    interval: 100ms
    priority: 5
    watchdog: 100ms
    programs:
      - {{name: flooder, program: "{here}:Flooder", bind: {{flags: [{flags}]}}, params: {{per_scan: {per_scan}}}}}
servers:
  modbus: {{enabled: false}}
  hmi: {{enabled: false}}
  opcua: {{enabled: {str(opcua).lower()}, endpoint: "opc.tcp://127.0.0.1:0/softplc/"}}
"""
    if alarms:
        text += """
alarms:
  definitions:
    - {name: "{flag}_on", for_each: flag, discrete: {tag: "{flag}_x", value: true}, priority: high}
"""
    return text


async def run(directory: Path, seconds: float, count: int, per_scan: int, alarms: bool, opcua: bool) -> dict[str, float]:
    path = directory / "tagdb.yaml"
    path.write_text(plant(count, per_scan, alarms, opcua))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=directory / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    published = [0]
    runtime.events.subscribe(lambda event: published.__setitem__(0, published[0] + 1), kinds=("alarm",))
    evaluation: list[float] = []
    alarm_adapter = next((adapter for adapter in runtime.adapters if adapter.name == "alarms"), None)
    if alarm_adapter is not None:
        evaluate = alarm_adapter.evaluate

        def timed() -> None:
            started = time.perf_counter()
            evaluate()
            evaluation.append((time.perf_counter() - started) * 1e3)

        alarm_adapter.evaluate = timed  # type: ignore[method-assign]
    await runtime.start()
    try:
        await asyncio.sleep(WARMUP_S)
        for task in runtime.tasks:
            task.stats.reset()
        counted_from, evaluation[:] = published[0], []
        await asyncio.sleep(seconds)
        fast, flood = (next(task for task in runtime.tasks if task.name == name) for name in ("fast", "flood"))
        figures = {
            "transitions_per_s": (published[0] - counted_from) / seconds,
            "latency_p99": fast.stats.latency.summary()["p99"], "latency_max": fast.stats.latency.summary()["max"],
            "fast_overruns": fast.stats.overruns, "flood_overruns": flood.stats.overruns,
            "flood_scan_p99": flood.stats.scan.summary()["p99"],
            "evaluate_p99": sorted(evaluation)[int(len(evaluation) * 0.99)] if evaluation else 0.0,
            "evaluate_max": max(evaluation, default=0.0),
        }
    finally:
        await runtime.stop()
    figures["published"] = published[0]
    store = directory / "state" / "alarms.sqlite"
    if store.exists():
        with sqlite3.connect(store) as connection:
            figures["journaled"] = connection.execute("SELECT COUNT(*) FROM alarm_journal").fetchone()[0]
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--alarms", type=int, default=1000, help="discrete alarms (default 1000)")
    parser.add_argument("--per-scan", type=int, default=100, help="flags flipped per 100 ms scan (default 100: 1,000 transitions/s)")
    parser.add_argument("--opcua", action="store_true", help="also serve OPC UA (the conditions get every event)")
    args = parser.parse_args()
    print(f"# {args.alarms} alarms, {args.per_scan * 10} flips/s for {args.seconds:g} s{' + OPC UA' if args.opcua else ''}; "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for alarms in (True, False):
        with tempfile.TemporaryDirectory(prefix="softplc-flood-") as directory:
            result = asyncio.run(run(Path(directory), args.seconds, args.alarms, args.per_scan, alarms, args.opcua))
        name = "flood" if alarms else "baseline (no alarms)"
        print(f"{name}: 10 ms task start latency p99 {result['latency_p99']:.3f} ms, max {result['latency_max']:.3f} ms, "
              f"overruns {result['fast_overruns']:.0f} (10 ms) / {result['flood_overruns']:.0f} (100 ms); "
              f"100 ms scan p99 {result['flood_scan_p99']:.2f} ms")
        if alarms:
            every = "every transition journaled" if result.get("journaled") == result["published"] else "ROWS MISSING"
            print(f"  {result['transitions_per_s']:.0f} transitions/s; {result['published']:.0f} published, "
                  f"{result.get('journaled', 0):.0f} journaled ({every}); alarm evaluation per boundary p99 "
                  f"{result['evaluate_p99']:.2f} ms, max {result['evaluate_max']:.2f} ms")
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
