"""An alarm flood of 10,000 transitions/s: the plant keeps scanning, clients are answered, nothing is lost unsaid.

Goals (issue 23, item 4), each printed with GOAL MISSED when missed:
- >= 95 % of the 100 ms task's cycles run during the flood (cycles / (cycles + overruns));
- a real `softplc read` (a new process, from its start to its exit) answers in <= 1 s meanwhile, every time;
- the journal complete: one row per transition published;
- an OPC UA event subscriber (asyncua, another process) gets every event or an EventQueueOverflow
  event where events were left out: no silent gap, its session lives through the flood and it
  never waits more than 2 s for a notification (a stalled server);
- the flood itself flagged: `_sys.alarms.flood` true during it.

A plant on the real clock with --alarms discrete alarms on bool tags: a 100 ms task flips
--per-scan of them every scan (1,000 of 1,000 = 10,000 transitions/s, half activations, half
returns to normal) while the tag `flooding` is true, beside a 10 ms task whose start latency is
reported. The OPC UA server serves on a free loopback port; the journal is the default SQLite
store. The same plant without its `alarms:` section runs second as the baseline (what a
`softplc read` costs on this machine at all, and the scan without alarms).

Silent gaps: every transition flips its alarm's ActiveState, so two events of one condition
with the same ActiveState mean events were left out between them; that is allowed only if an
EventQueueOverflow event arrived in between.

    .venv/bin/python bench/alarms_flood.py                       # 10 s flood + 10 s baseline
    .venv/bin/python bench/alarms_flood.py --seconds 30 --per-scan 100   # 1,000 transitions/s
    .venv/bin/python bench/alarms_flood.py --profile flood.prof  # cProfile of the runtime during the flood
    .venv/bin/python bench/alarms_flood.py --simulated           # CPU per transition, simulated clock, no servers
    chrt -f 5 .venv/bin/python bench/alarms_flood.py             # on a busy shared machine (SCHED_FIFO; root)
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import json
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc import InOut, Input, Param, Program  # noqa: E402

WARMUP_S = 2.0
DRAIN_S = 5.0  # after the flood: time for the subscriber to receive the tail
GOALS = {"cycles_run": 95.0, "read_max_s": 1.0, "silence_s": 2.0}  # silence: the subscriber heard nothing that long (a stalled server)


class Flooder(Program):
    """Flips `per_scan` of its flags every scan, round robin, while `enabled` is true."""

    flags = InOut("the flags")
    enabled = Input("flood while true")
    per_scan = Param(100, "flags flipped per scan")

    def setup(self) -> None:
        self.cursor = 0

    def scan(self) -> None:
        if not self.enabled:
            return
        flags = self.flags
        for _ in range(self.per_scan):
            flags[self.cursor] = not flags[self.cursor]
            self.cursor = (self.cursor + 1) % len(flags)


class Ticker(Program):
    """The 10 ms task's small scan."""

    count = InOut("scan counter")

    def scan(self) -> None:
        self.count = (self.count + 1) % 2**32


def plant(count: int, per_scan: int, alarms: bool) -> str:
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
  flooding: {{type: bool}}
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
      - {{name: flooder, program: "{here}:Flooder", bind: {{flags: [{flags}], enabled: flooding}}, params: {{per_scan: {per_scan}}}}}
servers:
  modbus: {{enabled: false}}
  hmi: {{enabled: false}}
  opcua: {{endpoint: "opc.tcp://127.0.0.1:0/softplc/"}}
"""
    if alarms:
        text += """
alarms:
  definitions:
    - {name: "{flag}_on", for_each: flag, discrete: {tag: "{flag}_x", value: true}, priority: high}
"""
    return text


# -- the subscriber (another process) -------------------------------------------------------------


async def subscribe(endpoint: str) -> None:
    """Count alarm events and overflow events on the Server object until stdin closes; print JSON."""
    from asyncua import Client, ua

    overflow_type = ua.NodeId(ua.ObjectIds.EventQueueOverflowEventType)
    figures: dict[str, Any] = {"events": 0, "overflows": 0, "silent_gaps": 0, "covered_gaps": 0, "max_silence_s": 0.0, "error": ""}
    last_active: dict[str, tuple[bool, int]] = {}  # condition → (ActiveState, overflows seen when it arrived)
    last_arrival = [0.0]
    flooding = [False]

    class Handler:
        def event_notification(self, event: Any) -> None:
            now = time.monotonic()
            if flooding[0] and last_arrival[0]:
                figures["max_silence_s"] = max(figures["max_silence_s"], now - last_arrival[0])
            last_arrival[0] = now
            fields = event.get_event_props_as_fields_dict()
            if fields["EventType"].Value == overflow_type:
                figures["overflows"] += 1
                return
            figures["events"] += 1
            name, active = fields["ConditionName"].Value, fields["ActiveState/Id"].Value
            previous = last_active.get(name)
            if previous is not None and previous[0] == active:
                figures["covered_gaps" if figures["overflows"] > previous[1] else "silent_gaps"] += 1
            last_active[name] = (active, figures["overflows"])

        def status_change_notification(self, status: Any) -> None:
            figures["error"] = f"status change {status}"

    try:
        async with Client(endpoint, timeout=10) as client:
            subscription = await client.create_subscription(100, Handler())
            await subscription.subscribe_events(client.nodes.server, [client.get_node(ua.NodeId(ua.ObjectIds.AlarmConditionType))])
            print("ready", flush=True)
            loop = asyncio.get_running_loop()
            while True:
                line = await loop.run_in_executor(None, sys.stdin.readline)
                if line.strip() == "flood":
                    flooding[0], last_arrival[0] = True, time.monotonic()
                elif line.strip() == "calm":
                    flooding[0] = False
                else:
                    break
            await client.get_node(ua.ObjectIds.Server_ServerStatus_State).read_value()  # the session still answers
    except Exception as error:  # noqa: BLE001 — reported, the bench judges it
        figures["error"] = f"{type(error).__name__}: {error}"
    print(json.dumps(figures), flush=True)


# -- the runtime under test -----------------------------------------------------------------------


def softplc_read(endpoint: str, directory: Path) -> tuple[float, bool]:
    """Wall seconds of one `softplc read ticks` (a new process), and whether it answered."""
    started = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", "import sys; from softplc.app.cli import main; sys.exit(main())", "read", "ticks", "--endpoint", endpoint],
        cwd=directory, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=60,
    )
    return time.perf_counter() - started, done.returncode == 0 and "ticks" in done.stdout


async def run(directory: Path, seconds: float, count: int, per_scan: int, alarms: bool, read_every: float,
              profile: Path | None) -> dict[str, Any]:
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.config import load_config
    from softplc.core.clock import RealClock
    from softplc.core.tagdb import Origin

    path = directory / "tagdb.yaml"
    path.write_text(plant(count, per_scan, alarms))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=directory / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    published = [0]
    runtime.events.subscribe(lambda event: published.__setitem__(0, published[0] + 1), kinds=("alarm",))
    await runtime.start()
    endpoint = next(adapter for adapter in runtime.adapters if adapter.name == "opcua").endpoint
    subscriber = await asyncio.create_subprocess_exec(
        sys.executable, __file__, "--subscriber", endpoint, stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
        env={**os.environ, "PYTHONPATH": str(REPO)})
    assert subscriber.stdin is not None and subscriber.stdout is not None
    figures: dict[str, Any] = {}
    driver = Origin("bench", role=None)
    try:
        assert (await asyncio.wait_for(subscriber.stdout.readline(), 30)).strip() == b"ready", "the subscriber did not start"
        await asyncio.sleep(WARMUP_S)
        calm_read = await asyncio.to_thread(softplc_read, endpoint, directory)  # what a read costs here without a flood
        tasks = {task.name: task for task in runtime.tasks}
        for task in tasks.values():
            task.stats.reset()
        counted_from = published[0]
        profiler = cProfile.Profile() if profile is not None else None
        subscriber.stdin.write(b"flood\n")
        runtime.db.submit([("flooding", True)], driver)
        if profiler is not None:
            profiler.enable()
        started, cpu_started = time.monotonic(), time.process_time()
        reads: list[tuple[float, bool]] = []
        flagged = False
        while time.monotonic() - started < seconds:
            reads.append(await asyncio.to_thread(softplc_read, endpoint, directory))
            if "_sys.alarms.flood" in runtime.db and runtime.db.value("_sys.alarms.flood") is True:
                flagged = True
            await asyncio.sleep(max(0.0, min(read_every - reads[-1][0], seconds - (time.monotonic() - started))))
        runtime.db.submit([("flooding", False)], driver)
        if profiler is not None:
            profiler.disable()
            profiler.dump_stats(profile)  # type: ignore[arg-type]
        elapsed, cpu = time.monotonic() - started, time.process_time() - cpu_started
        fast, flood = tasks["fast"].stats, tasks["flood"].stats
        figures = {
            "elapsed": elapsed, "transitions_per_s": (published[0] - counted_from) / elapsed,
            "cycles": flood.cycles, "overruns": flood.overruns, "cycles_run": 100.0 * flood.cycles / max(1, flood.cycles + flood.overruns),
            "flood_latency_max": flood.latency.summary()["max"],
            "fast_latency_p99": fast.latency.summary()["p99"], "fast_latency_max": fast.latency.summary()["max"],
            "fast_cycles_run": 100.0 * fast.cycles / max(1, fast.cycles + fast.overruns),
            "reads": len(reads), "read_max_s": max(wall for wall, _ in reads), "read_median_s": sorted(wall for wall, _ in reads)[len(reads) // 2],
            "reads_failed": sum(1 for _, answered in reads if not answered), "flagged": flagged, "calm_read_s": calm_read[0],
            "cpu_share": 100.0 * cpu / elapsed,
        }
        subscriber.stdin.write(b"calm\n")
        await asyncio.sleep(DRAIN_S)
    finally:
        if subscriber.returncode is None:
            subscriber.stdin.close()
        try:
            line = await asyncio.wait_for(subscriber.stdout.readline(), 30)
            figures["subscriber"] = json.loads(line) if line.strip() else {"error": "no answer"}
        except asyncio.TimeoutError:
            subscriber.kill()
            figures["subscriber"] = {"error": "the subscriber hung"}
        await subscriber.wait()
        await runtime.stop()
    figures["published"] = published[0]
    store = directory / "state" / "alarms.sqlite"
    if store.exists():
        with sqlite3.connect(store) as connection:
            figures["journaled"] = connection.execute("SELECT COUNT(*) FROM alarm_journal").fetchone()[0]
    return figures


async def simulated_cost(directory: Path, count: int, per_scan: int, seconds: float) -> tuple[int, float, float]:
    """The alarm engine alone (no servers) on the simulated clock: transitions, CPU s in evaluations (journal rows included), process CPU s."""
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.config import load_config
    from softplc.core.clock import SimClock
    from softplc.core.tagdb import Origin

    path = directory / "tagdb.yaml"
    path.write_text(plant(count, per_scan, True).replace('opcua: {endpoint: "opc.tcp://127.0.0.1:0/softplc/"}', "opcua: {enabled: false}"))
    config = load_config(path)
    runtime = Runtime(config, SimClock(), state_dir=directory / "state", retain=False)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    alarms = next(adapter for adapter in runtime.adapters if adapter.name == "alarms")
    evaluate, spent = alarms.evaluate, [0.0]

    def timed() -> None:
        started = time.thread_time()
        evaluate()
        spent[0] += time.thread_time() - started

    alarms.evaluate = timed  # type: ignore[method-assign]
    published = [0]
    runtime.events.subscribe(lambda event: published.__setitem__(0, published[0] + 1), kinds=("alarm",))

    async def flood() -> None:
        await runtime.running.wait()
        runtime.db.submit([("flooding", True)], Origin("bench", role=None))

    runtime.spawn(flood(), "flood")
    cpu = time.process_time()
    await runtime.run(duration=seconds)
    return published[0], spent[0], time.process_time() - cpu


def verdict(met: bool) -> str:
    return "met" if met else "GOAL MISSED"


def report(name: str, result: dict[str, Any], alarms: bool) -> None:
    print(f"{name}: 100 ms task {result['cycles']} cycles, {result['overruns']} overruns: "
          f"{result['cycles_run']:.1f} % run ({verdict(result['cycles_run'] >= GOALS['cycles_run']) if alarms else 'reference'}); "
          f"its start latency max {result['flood_latency_max']:.0f} ms; 10 ms task {result['fast_cycles_run']:.1f} % run, "
          f"latency p99 {result['fast_latency_p99']:.2f} ms, max {result['fast_latency_max']:.1f} ms; "
          f"the runtime's process used {result['cpu_share']:.0f} % of a core")
    read_ok = result["read_max_s"] <= GOALS["read_max_s"] and not result["reads_failed"]
    print(f"  softplc read: {result['reads']} reads, median {result['read_median_s']:.2f} s, max {result['read_max_s']:.2f} s, "
          f"{result['reads_failed']} failed ({verdict(read_ok) if alarms else 'reference'}); before the flood {result['calm_read_s']:.2f} s")
    if not alarms:
        return
    subscriber = result["subscriber"]
    journal_ok = result.get("journaled") == result["published"]
    print(f"  {result['transitions_per_s']:.0f} transitions/s; journal: {result['published']} published, {result.get('journaled', 0)} rows "
          f"({verdict(journal_ok)})")
    events_ok = not subscriber.get("error") and subscriber.get("silent_gaps", 1) == 0 and (
        subscriber.get("events", 0) >= result["published"] or subscriber.get("overflows", 0) > 0) and (
        subscriber.get("max_silence_s", 0.0) <= GOALS["silence_s"])
    print(f"  OPC UA subscriber: {subscriber.get('events', 0)} events, {subscriber.get('overflows', 0)} overflow events, "
          f"{subscriber.get('covered_gaps', 0)} gaps announced, {subscriber.get('silent_gaps', 0)} silent gaps, "
          f"longest silence {subscriber.get('max_silence_s', 0):.2f} s{', error: ' + subscriber['error'] if subscriber.get('error') else ''} "
          f"({verdict(events_ok)})")
    print(f"  flood flagged (_sys.alarms.flood): {'yes' if result['flagged'] else 'no'} ({verdict(result['flagged'])})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--alarms", type=int, default=1000, help="discrete alarms (default 1000)")
    parser.add_argument("--per-scan", type=int, default=1000, help="flags flipped per 100 ms scan (default 1000: 10,000 transitions/s)")
    parser.add_argument("--read-every", type=float, default=1.0, help="seconds between the starts of two `softplc read`s")
    parser.add_argument("--profile", type=Path, help="write a cProfile of the runtime during the flood here")
    parser.add_argument("--no-baseline", action="store_true", help="only the flood")
    parser.add_argument("--simulated", action="store_true",
                        help="only the CPU cost per transition: the alarm engine and its journal on the simulated clock, no servers")
    parser.add_argument("--subscriber", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber:
        asyncio.run(subscribe(args.subscriber))
        return
    if args.simulated:
        with tempfile.TemporaryDirectory(prefix="softplc-flood-") as directory:
            transitions, evaluating, process = asyncio.run(simulated_cost(Path(directory), args.alarms, args.per_scan, args.seconds))
        print(f"simulated {args.seconds:g} s: {transitions} transitions; evaluation (with the journal rows) {evaluating:.2f} s of CPU = "
              f"{evaluating / max(1, transitions) * 1e6:.1f} µs a transition; the whole process {process:.2f} s of CPU")
        return
    print(f"# {args.alarms} alarms, {args.per_scan * 10} transitions/s for {args.seconds:g} s, OPC UA subscriber, "
          f"softplc read every {args.read_every:g} s; load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for alarms in (True, False) if not args.no_baseline else (True,):
        with tempfile.TemporaryDirectory(prefix="softplc-flood-") as directory:
            result = asyncio.run(run(Path(directory), args.seconds, args.alarms, args.per_scan, alarms, args.read_every,
                                     args.profile if alarms else None))
        report("flood" if alarms else "baseline (no alarms)", result, alarms)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
