"""Trend query time: one tag sampled every second, plotted over 1 day and 30 days in <= 2,000 points.

Builds a store (SQLite in a temp dir, or PostgreSQL with --dsn) holding --days days of one tag at
1 Hz (86,400 samples a day) written through the historian's own writer, then times
`HistoryReader.plot()` for the last day and for the whole span (--repeat times each; median and
worst), and a raw read of one day for comparison.

Goals (issue 16): 1 day decimated to <= 2,000 points in <= 100 ms; 30 days in <= 500 ms.

    .venv/bin/python bench/history_query.py
    .venv/bin/python bench/history_query.py --dsn "host=127.0.0.1 port=5432 user=postgres dbname=postgres"
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.timing import load_average  # noqa: E402
from softplc.adapters.history.queries import HistoryReader  # noqa: E402
from softplc.adapters.history.store import HistorySink, TagInfo  # noqa: E402
from softplc.storage import BatchWriter, Database, StorageSettings  # noqa: E402

T0 = 1_767_225_600.0
DAY = 86_400
GOALS = {1: 100.0, 30: 500.0}  # days → ms


def fill(database: Database, days: int) -> float:
    sink = HistorySink("bench", [TagInfo("level", "float64", "%")])
    writer = BatchWriter(database, flush_period=0.2)
    writer.register(sink)
    error = writer.start()
    if error is not None:
        raise SystemExit(f"cannot open {database.describe()}: {error}")
    started = time.monotonic()
    for day in range(days):
        base = T0 + day * DAY
        rows = [("level", base + t, 50 + 40 * math.sin((base + t) / 3600.0), 0) for t in range(DAY)]  # quality code 0: good
        rows[DAY // 2] = ("level", base + DAY // 2, 150.0, 0)  # a daily one-second spike
        writer.put("history", rows)
        writer.flush(timeout=600)
    writer.stop()
    return time.monotonic() - started


def timed(function, repeat: int) -> tuple[float, float, object]:
    durations = []
    result = None
    for _ in range(repeat):
        started = time.perf_counter()
        result = function()
        durations.append((time.perf_counter() - started) * 1e3)
    return statistics.median(durations), max(durations), result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=int, default=30)
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--dsn", help="PostgreSQL instead of SQLite (the tables are created in its current schema)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="softplc-query-") as directory:
        settings = StorageSettings.postgresql(args.dsn) if args.dsn else StorageSettings.sqlite(Path(directory) / "history.sqlite")
        database = Database(settings)
        load_before = load_average()
        seconds = fill(database, args.days)
        print(f"{'PostgreSQL' if args.dsn else 'SQLite'}: {args.days * DAY:,} samples of one tag written in {seconds:.1f} s "
              f"({args.days * DAY / seconds:,.0f}/s); load before {load_before}")
        reader = HistoryReader(database, "bench")
        end = T0 + args.days * DAY
        for days in sorted({1, args.days}):
            start = end - days * DAY
            median, worst, plot = timed(lambda: reader.plot("level", start, end, args.points), args.repeat)
            values = [s.value for s in plot.samples]
            spikes = sum(1 for v in values if v == 150.0)
            goal = GOALS.get(days)
            verdict = "" if goal is None else f"; goal <= {goal:g} ms: {'met' if worst <= goal else 'MISSED'}"
            print(f"  plot {days:>2} day(s) → {len(plot.samples)} points ({spikes} of {days} spikes kept): "
                  f"median {median:.1f} ms, worst {worst:.1f} ms{verdict}")
        median, worst, page = timed(lambda: reader.raw("level", end - DAY, end), 3)
        print(f"  raw read of 1 day ({len(page.samples):,} samples), for comparison: median {median:.1f} ms")
        reader.close()
        print(f"  load after {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
