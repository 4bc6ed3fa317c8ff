"""OPC UA HistoryRead over the historian: reply times, and the 10 ms task's start latency meanwhile.

An in-process runtime on the real clock records into a SQLite store pre-filled with one day of
one tag at 1 Hz (86,400 samples); its OPC UA server answers an asyncua client in a child process
(so the client's decoding does not run on the runtime's loop). The client reads the whole day raw
page by page (MaxReturnDataValues = 1,000 per call, following continuation points), then the day
as 1-minute Averages (1,440 intervals, two calls), again and again for --seconds. A 10 ms probe
task's start latency is measured first while no client reads (--idle s), then while it reads.

No goal was set for HistoryRead; the figures show what a client paging through history costs
the scan (building and encoding each reply runs on the scan's event loop).

    .venv/bin/python bench/history_read.py
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.timing import load_average  # noqa: E402

CORE = REPO / "tests" / "core_programs.py"
DAY = 86_400
START = (time.time() // DAY - 2) * DAY  # the pre-filled day: the day before yesterday (inside the 30-day retention)

PLANT = f"""
version: 1
plant: {{name: reads}}
tags:
  probe_count: {{type: uint32}}
  level: {{type: float64, history: true}}
tasks:
  probe:
    interval: 10ms
    programs:
      - {{name: probe, program: "{CORE}:Counter", bind: {{count: probe_count}}}}
servers:
  opcua: {{endpoint: "opc.tcp://127.0.0.1:0/softplc/", security: [None]}}
  modbus: {{enabled: false}}
  hmi: {{enabled: false}}
history: {{flush_period: 1s}}
"""


def prefill(state: Path) -> None:
    from softplc.adapters.history.store import HistorySink, TagInfo
    from softplc.storage import BatchWriter, Database, StorageSettings

    writer = BatchWriter(Database(StorageSettings.sqlite(state / "history.sqlite")), flush_period=0.1)
    writer.register(HistorySink("reads", [TagInfo("level", "float64")]))
    assert writer.start() is None
    writer.put("history", [("level", START + t, 50.0 + (t % 600) / 10, 0) for t in range(DAY)])  # quality code 0: good
    assert writer.flush(timeout=120)
    writer.stop()


async def serve(args: argparse.Namespace, state: Path) -> None:
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.config import parse_config
    from softplc.core.clock import RealClock
    from tests.opcua_support import add_users

    add_users(state)
    config = parse_config(PLANT, state / "tagdb.yaml")
    runtime = Runtime(config, RealClock(), state_dir=state)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    try:
        server = next(adapter for adapter in runtime.adapters if adapter.name == "opcua")
        probe = next(task for task in runtime.tasks if task.name == "probe")
        await asyncio.sleep(2.0)
        probe.stats.latency.reset()
        await asyncio.sleep(args.idle)
        idle = probe.stats.latency.summary()
        probe.stats.latency.reset()
        child = await asyncio.create_subprocess_exec(sys.executable, __file__, "--client", server.endpoint, "--seconds", str(args.seconds),
                                                     *(["--raw-only"] if args.raw_only else []),
                                                     stdout=asyncio.subprocess.PIPE, cwd=REPO)
        out, _ = await child.communicate()
        busy = probe.stats.latency.summary()
    finally:
        await runtime.stop()
    seen = json.loads(out.decode().strip().splitlines()[-1])
    print(f"HistoryRead, SQLite, one day of 1 Hz samples (load before {args.load}, after {load_average()})")
    for kind in ("raw", "processed"):
        calls = seen[kind]
        if not calls:
            continue
        print(f"  {kind}: {len(calls)} calls, reply median {statistics.median(calls):.1f} ms, "
              f"p99 {sorted(calls)[int(len(calls) * 0.99) - 1]:.1f} ms, max {max(calls):.1f} ms")
    print(f"  whole day raw: {seen['day_raw_s']:.2f} s ({DAY / seen['day_raw_s']:,.0f} values/s) in {seen['pages']} pages")
    print(f"  10 ms probe start latency idle: p99 {idle['p99']:.3f} ms, max {idle['max']:.3f} ms; "
          f"while reading: p99 {busy['p99']:.3f} ms, max {busy['max']:.3f} ms")


async def client(endpoint: str, seconds: float, raw_only: bool = False) -> None:
    from datetime import datetime, timezone

    from asyncua import Client, ua

    def stamp(t: float) -> datetime:
        return datetime.fromtimestamp(t, timezone.utc)

    raw_calls: list[float] = []
    processed_calls: list[float] = []
    day_raw, pages = 0.0, 0
    from tests.opcua_support import PASSWORDS

    connection = Client(endpoint, timeout=30)
    connection.set_user("viewer")
    connection.set_password(PASSWORDS["viewer"])
    async with connection:
        ns = await connection.get_namespace_index("urn:softplc:tags")
        node = ua.NodeId("level", ns)
        raw = ua.ReadRawModifiedDetails(IsReadModified=False, StartTime=stamp(START), EndTime=stamp(START + DAY), NumValuesPerNode=0)
        average = ua.ReadProcessedDetails(StartTime=stamp(START), EndTime=stamp(START + DAY), ProcessingInterval=60_000,
                                          AggregateType=[ua.NodeId(ua.ObjectIds.AggregateFunction_Average)])
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            for details, calls in ((raw, raw_calls), (average, processed_calls))[:2 if not raw_only else 1]:
                point, began, count = b"", time.perf_counter(), 0
                while True:
                    started = time.perf_counter()
                    params = ua.HistoryReadParameters(HistoryReadDetails=details, TimestampsToReturn=ua.TimestampsToReturn.Source,
                                                      ReleaseContinuationPoints=False,  # asyncua defaults to True
                                                      NodesToRead=[ua.HistoryReadValueId(NodeId=node, ContinuationPoint=point)])
                    (result,) = await connection.uaclient.history_read(params)
                    if not result.StatusCode.is_good():
                        raise SystemExit(f"HistoryRead failed: {result.StatusCode}")
                    calls.append((time.perf_counter() - started) * 1000)
                    count += 1
                    point = result.ContinuationPoint
                    if not point:
                        break
                if details is raw and count > 1:
                    day_raw, pages = time.perf_counter() - began, count
    print(json.dumps({"raw": raw_calls, "processed": processed_calls, "day_raw_s": day_raw, "pages": pages}))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="how long the client reads")
    parser.add_argument("--idle", type=float, default=10.0, help="seconds measured before the client starts")
    parser.add_argument("--raw-only", action="store_true", help="the client reads raw values only (no processed reads)")
    parser.add_argument("--client", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        asyncio.run(client(args.client, args.seconds, args.raw_only))
        return 0
    args.load = load_average()
    with tempfile.TemporaryDirectory(prefix="softplc-history-read-") as directory:
        state = Path(directory)
        prefill(state)
        asyncio.run(serve(args, state))
    return 0


if __name__ == "__main__":
    sys.exit(main())
