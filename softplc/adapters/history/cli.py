"""`softplc history export TAGS --from --to [--format csv|json]` and `softplc history tags`.

Reads the store directly (a second connection: SQLite's WAL lets it read while the runtime
writes), so it works with the plant running or stopped. Times: ISO 8601 (UTC unless a zone is
given), Unix seconds, or `-DURATION` (before the end of the recorded history, e.g. `-1h`).
"""

from __future__ import annotations

import argparse
import csv
import fnmatch
import json
import math
import sys
from pathlib import Path
from typing import Any, TextIO

from softplc.adapters.history.aggregates import Aggregate
from softplc.util.plurals import plural
from softplc.util.timestamps import format_utc, parse_utc

EXIT_OK, EXIT_FAILURE, EXIT_CONFIG = 0, 1, 2


def add_commands(subparsers: Any) -> None:
    """Register `history` with the softplc command line."""
    history = subparsers.add_parser(
        "history",
        help="recorded history: list tags, export values",
        description="Read the history recorded by `softplc run` (the history: section of CONFIG), "
        "while the plant runs or after. --sim reads the history of the last simulated run.",
        epilog="Examples: softplc history tags | softplc history export 'r01_*' --from=-10min | "
        "softplc history export t01_iBL --from 2026-01-01T00:00:00 --to 2026-01-01T01:00:00 --interval 1min --format json",
    )
    commands = history.add_subparsers(title="subcommands", metavar="SUBCOMMAND")
    tags = commands.add_parser("tags", help="list the tags that have history, with their first and last sample")
    _common(tags)
    tags.set_defaults(func=cmd_tags)
    export = commands.add_parser("export", help="write the history of tags as CSV or JSON")
    export.add_argument("tags", nargs="+", metavar="TAG", help="tag names or glob patterns (r01_*)")
    export.add_argument("--from", dest="start", metavar="TIME", help="start: ISO 8601, UTC unless a zone is given (2026-01-01T08:00), Unix seconds, or -DURATION "
                        "before the last sample (--from=-10min); default: the first sample")
    export.add_argument("--to", dest="end", metavar="TIME", help="end, excluded (same forms; default: after the last sample)")
    export.add_argument("--format", choices=("csv", "json"), default="csv")
    export.add_argument("--interval", metavar="DURATION", help="one processed value per interval instead of the raw samples")
    export.add_argument("--aggregate", default="time_average", choices=[a.value for a in Aggregate],
                        help="with --interval: which value per interval, OPC UA Part 13's (default time_average: time-weighted; "
                             "average is the plain mean of the stored values)")
    export.add_argument("--output", "-o", type=Path, metavar="FILE", help="write to FILE instead of standard output")
    _common(export)
    export.set_defaults(func=cmd_export)
    history.set_defaults(func=lambda args: (history.print_help(), EXIT_FAILURE)[1])


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default="tagdb.yaml", help="plant configuration (default tagdb.yaml)")
    parser.add_argument("--state-dir", type=Path, metavar="DIR", help="state directory (default .softplc next to CONFIG)")
    parser.add_argument("--sim", action="store_true", help="the history of the last `softplc run --sim` (simulated time)")
    parser.add_argument("--plant", metavar="NAME", help="plant (runtime) name in a shared store (default: CONFIG's plant name)")


def _reader(args: argparse.Namespace) -> Any:
    from softplc.adapters.history.queries import HistoryReader
    from softplc.adapters.history.settings import HistorySettings
    from softplc.config import load_config
    from softplc.storage import Database

    config = load_config(args.config)
    if not HistorySettings.configured(config):
        raise _Failure(f"{args.config} has no history: section, so nothing is recorded (docs/history.md)")
    settings = HistorySettings.from_config(config)
    state_dir = args.state_dir or config.state_dir
    database = Database(settings.storage(state_dir, simulated=args.sim))
    if not database.exists():
        run = "softplc run --sim" if args.sim else "softplc run"
        raise _Failure(f"no history yet: {database.describe()} does not exist (it is created by `{run}`)")
    return HistoryReader(database, args.plant or config.name)


class _Failure(Exception):
    pass


def _run(args: argparse.Namespace, body: Any) -> int:
    from softplc.storage.database import driver_errors

    try:
        return body(args)
    except _Failure as failure:
        print(f"softplc: {failure}", file=sys.stderr)
        return EXIT_FAILURE
    except driver_errors() as error:
        print(f"softplc: cannot read history: {error}", file=sys.stderr)
        return EXIT_FAILURE


def cmd_tags(args: argparse.Namespace) -> int:
    return _run(args, _tags)


def _tags(args: argparse.Namespace) -> int:
    from softplc.util.console import print_table

    reader = _reader(args)
    tags = reader.historized()
    if not tags:
        raise _Failure(f"no history of plant '{reader.plant}' in {reader.database.describe()}" + _other_plants(reader))
    rows = []
    for name, info in tags.items():
        span = reader.span(name)
        first, last = (format_utc(span[0]), format_utc(span[1])) if span else ("", "")
        rows.append([name, info.type, info.unit, "stepped" if info.stepped else "sloped", first, last])
    print_table(rows, ("tag", "type", "unit", "interpolation", "first", "last"))
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    return _run(args, _export)


def _export(args: argparse.Namespace) -> int:
    from softplc.storage import parse_span

    reader = _reader(args)
    known = reader.historized()
    names: list[str] = []
    for pattern in args.tags:
        hits = [name for name in known if fnmatch.fnmatchcase(name, pattern)]
        if not hits:
            sample = ", ".join(list(known)[:8]) + (" ..." if len(known) > 8 else "")
            raise _Failure(f"no history of '{pattern}' (plant '{reader.plant}'); tags with history: {sample or 'none'}" + _other_plants(reader))
        names += [hit for hit in hits if hit not in names]
    spans = [span for span in (reader.span(name) for name in names) if span]
    if not spans:
        raise _Failure(f"no samples of {', '.join(names)} in {reader.database.describe()}")
    last = max(span[1] for span in spans)
    end = parse_time(args.end, last) if args.end else math.nextafter(last, math.inf)
    start = parse_time(args.start, last) if args.start else min(span[0] for span in spans)
    if end <= start:
        raise _Failure(f"--to ({format_utc(end)}) must be after --from ({format_utc(start)})")
    series: dict[str, list[Any]] = {}
    for name in names:
        if args.interval:
            try:
                interval = parse_span(args.interval)
            except ValueError as error:
                raise _Failure(f"--interval: {error}") from None
            if interval <= 0 or (end - start) / interval > 10_000_000:
                raise _Failure(f"--interval {args.interval} is too small for this range")
            try:
                series[name] = reader.processed(name, start, end, interval, Aggregate(args.aggregate))
            except ValueError as error:
                raise _Failure(str(error)) from None
        else:
            series[name] = reader.raw(name, start, end).samples
    stream: TextIO = open(args.output, "w", newline="", encoding="utf-8") if args.output else sys.stdout
    try:
        if args.format == "json":
            document = {"plant": reader.plant, "from": format_utc(start), "to": format_utc(end),
                        "aggregate": args.aggregate if args.interval else "raw",
                        "tags": {name: [{"time": format_utc(s.time), "value": _json_value(s.value), "quality": s.quality.value}
                                        for s in samples] for name, samples in series.items()}}
            json.dump(document, stream, indent=1)
            stream.write("\n")
        else:
            writer = csv.writer(stream)
            writer.writerow(["tag", "time", "value", "quality"])
            for name, samples in series.items():
                writer.writerows([name, format_utc(s.time), "" if s.value is None else s.value, s.quality.value] for s in samples)
    finally:
        if args.output:
            stream.close()
    if args.output:
        count = sum(len(samples) for samples in series.values())
        print(f"wrote {plural(count, 'value')} of {plural(len(series), 'tag')} to {args.output}", file=sys.stderr)
    return EXIT_OK


def _other_plants(reader: Any) -> str:
    others = [plant for plant in reader.plants() if plant != reader.plant]
    return f" (the store also holds plants: {', '.join(others)}; use --plant)" if others else ""


def _json_value(value: Any) -> Any:
    return None if isinstance(value, float) and not math.isfinite(value) else value


def parse_time(text: str, last: float) -> float:
    """Unix seconds from ISO 8601 (UTC if no zone), a number, or -DURATION before `last`."""
    from softplc.storage import parse_span

    text = text.strip()
    if text.startswith("-"):
        try:
            return last - parse_span(text[1:])
        except ValueError as error:
            raise _Failure(f"bad time {text!r}: {error}") from None
    try:
        return float(text)
    except ValueError:
        pass
    try:
        return parse_utc(text)
    except ValueError:
        raise _Failure(f"bad time {text!r}: write ISO 8601 (2026-01-01T08:00:00), Unix seconds, or -1h") from None
