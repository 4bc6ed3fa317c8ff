"""`softplc audit`: who wrote what, and who did what, when and from where — accepted or refused.

By default it reads the audit store of CONFIG's plant directly (STATE_DIR/audit.sqlite, or the
PostgreSQL server of the `audit:` section): it works while the plant runs (SQLite's WAL lets
it read beside the writer) and while it is stopped. With `--endpoint` it asks a running
runtime over OPC UA instead (the `audit.query` command, engineers only), so it works from
another machine. Exit statuses: 0 done (also when nothing matches), 1 the store cannot be read
or the runtime refused, 2 bad command line, 3 no connection, 4 not allowed (login refused, or
the session is not an engineer's).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import math
import sys
import time
from pathlib import Path
from typing import Any

from softplc.clients.endpoints import endpoint_url
from softplc.clients.login import LoginError, add_login_arguments, login_from_args
from softplc.core.commands import CommandRefused
from softplc.util.plurals import plural
from softplc.util.timestamps import TIME_HELP, format_shown, parse_time

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_NO_CONNECTION, EXIT_NOT_ALLOWED = 0, 1, 2, 3, 4
TABLE_LIMIT = 100  # rows a table shows unless --limit says otherwise (csv and json: every row)
PAGE = 1000  # rows per audit.query call
HEADER = ("time", "source", "user", "peer", "tag / command", "old", "new", "result")


def add_commands(subparsers: Any) -> None:
    """Register `audit` with the softplc command line."""
    audit = subparsers.add_parser(
        "audit", help="the audit trail: every write and command, accepted or refused, with who and from where",
        description="Show the audit trail of a plant, newest first: every client write (OPC UA, Modbus, the HMI, the live "
        "CLI) and every command (forcing, program control, alarm actions, resetting faults), accepted or refused, with "
        "the time, source, user, peer address, tag or command, old and new value and the rule broken. Reads the "
        "plant's audit store (works with the plant stopped); with --endpoint asks a running runtime over OPC UA "
        "(an engineer's login).",
        epilog="Examples: softplc audit --since 1h | softplc audit --tag 't01_*' --refused | softplc audit --by alice "
        "--since 2026-11-24T08:00 --format csv > audit.csv | softplc audit --command 'tags.*' --endpoint "
        "opc.tcp://plc7:4840/softplc/ --user eng",
    )
    what = audit.add_argument_group("what to show")
    what.add_argument("--since", metavar="TIME", help=f"from TIME: {TIME_HELP}")
    what.add_argument("--until", metavar="TIME", help="up to TIME, excluded (same forms)")
    what.add_argument("--tag", metavar="GLOB", help="writes of these tags, and commands acting on them (a force)")
    what.add_argument("--command", metavar="GLOB", help="calls of these commands (tags.force, 'alarms.*')")
    what.add_argument("--by", metavar="USER", help="entries of this user (--user logs in, with --endpoint)")
    what.add_argument("--source", metavar="SOURCE", help="opcua, modbus, hmi, cli... (a glob: 'fleet*')")
    what.add_argument("--peer", metavar="GLOB", help="client address, e.g. '10.0.0.7:*'")
    what.add_argument("--kind", choices=("write", "command"), help="only writes, or only commands")
    result = what.add_mutually_exclusive_group()
    result.add_argument("--refused", action="store_true", help="only what was refused")
    result.add_argument("--accepted", action="store_true", help="only what was carried out")
    what.add_argument("--limit", type=_count, metavar="N", help=f"at most N entries (default {TABLE_LIMIT} in a table, every one in csv and json)")
    what.add_argument("--format", choices=("table", "csv", "json"), default="table")
    what.add_argument("--output", "-o", type=Path, metavar="FILE", help="write to FILE instead of standard output")
    store = audit.add_argument_group("the plant's store (default)")
    store.add_argument("--config", default="tagdb.yaml", help="plant configuration (default tagdb.yaml)")
    store.add_argument("--state-dir", type=Path, metavar="DIR", help="state directory (default .softplc next to CONFIG)")
    store.add_argument("--sim", action="store_true", help="the trail of the last `softplc run --sim` (simulated time: "
                       "--since 10s counts back from its last entry)")
    store.add_argument("--plant", metavar="NAME", help="plant (runtime) name in a shared store, * for all (default CONFIG's)")
    audit.add_argument("--endpoint", metavar="URL", type=endpoint_url, help="ask the runtime serving OPC UA at URL instead (audit.query, engineers only)")
    add_login_arguments(audit, endpoint=False, user_help="; with --endpoint")
    audit.set_defaults(func=cmd_audit)


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, not {value}")
    return value


class _Failure(Exception):
    def __init__(self, message: str, status: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.status = status


def cmd_audit(args: argparse.Namespace) -> int:
    try:
        if args.user and not args.endpoint:
            raise _Failure(f"--user logs in to a runtime given by --endpoint; to show the entries of {args.user} write --by {args.user}", EXIT_USAGE)
        wanted = args.limit if args.limit is not None else (TABLE_LIMIT if args.format == "table" else math.inf)
        rows = _remote(args, wanted) if args.endpoint else _local(args, wanted)
        _show(args, rows)
    except _Failure as failure:
        print(f"softplc audit: {failure}", file=sys.stderr)
        return failure.status
    return EXIT_OK


def _arguments(args: argparse.Namespace, now: float) -> dict[str, Any]:
    """The audit.query arguments the options ask for (relative times counted back from `now`)."""
    arguments: dict[str, Any] = {"since": _time(args.since, "--since", now), "until": _time(args.until, "--until", now),
                                 "tag": args.tag, "command": args.command, "user": args.by, "source": args.source,
                                 "peer": args.peer, "kind": args.kind,
                                 "result": "refused" if args.refused else "accepted" if args.accepted else None}
    return {key: value for key, value in arguments.items() if value is not None and value != ""}


def _time(text: str | None, option: str, now: float) -> float | None:
    if not text:
        return None
    try:
        return parse_time(text, now)
    except ValueError as error:
        raise _Failure(f"{option} {error}", EXIT_USAGE) from None


# -- reading the store ------------------------------------------------------------------------


def _local(args: argparse.Namespace, wanted: float) -> list[dict[str, Any]]:
    from softplc.config import load_config
    from softplc.storage import Database
    from softplc.storage.audit.queries import MAX_ROWS, AuditQuery, query_from_arguments, search
    from softplc.storage.audit.settings import AuditSettings
    from softplc.storage.database import driver_errors

    config = load_config(args.config)  # a ConfigError is reported by the CLI (exit 2)
    settings = AuditSettings.from_config(config)
    database = Database(settings.storage(args.state_dir or config.state_dir, simulated=args.sim))
    if not database.exists():
        run = "softplc run --sim" if args.sim else "softplc run"
        raise _Failure(f"no audit trail yet: {database.describe()} does not exist (it is created by `{run}`)")
    plant = config.name
    try:
        now = time.time()
        if args.sim:  # simulated time: count back from the run's last entry
            last = search(database, AuditQuery(plant=args.plant, limit=1), plant)
            now = last[0].time if last else now
        query = query_from_arguments({**_arguments(args, now), "plant": args.plant})
        rows: list[dict[str, Any]] = []
        while len(rows) < wanted:
            page = search(database, _page(query, len(rows), int(min(MAX_ROWS, wanted - len(rows)))), plant)
            rows += [entry.to_dict() for entry in page]
            if len(page) < MAX_ROWS:
                break
    except CommandRefused as refused:
        raise _Failure(str(refused).removeprefix("audit.query: "), EXIT_USAGE) from None
    except driver_errors() as error:
        raise _Failure(f"cannot read {database.describe()}: {str(error).strip() or type(error).__name__}") from None
    if not rows and not settings.enabled:
        print(f"softplc audit: note: {args.config} says audit: {{enabled: false}}: nothing is being recorded", file=sys.stderr)
    return rows


def _page(query: Any, offset: int, limit: int) -> Any:
    import dataclasses

    return dataclasses.replace(query, offset=offset, limit=limit)


# -- asking a running runtime -----------------------------------------------------------------


def _remote(args: argparse.Namespace, wanted: float) -> list[dict[str, Any]]:
    if getattr(args, "verbose", 0) < 2:
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)  # this command reports what asyncua would warn about
    arguments = _arguments(args, time.time())
    if args.plant:
        arguments["plant"] = args.plant
    args.endpoint = args.endpoint.strip()
    try:
        login = login_from_args(args)
    except LoginError as error:
        raise _Failure(str(error), error.exit_status) from None

    async def session() -> list[dict[str, Any]]:
        from softplc.clients.door_client import CommandError, call_pages
        from softplc.clients.session import NotSoftplc, open_live_session

        try:
            async with open_live_session(login) as live:
                return await call_pages(live.client, live.ns, "audit.query", arguments, wanted, PAGE)
        except NotSoftplc as error:
            raise _Failure(f"{login.endpoint}: {error}", EXIT_NO_CONNECTION) from None
        except CommandError as error:
            if error.not_allowed:
                who = f"user {login.user!r}" if login.user else "an anonymous session"
                raise _Failure(f"reading the audit trail needs the engineer role, and {who} does not have it: "
                               "log in with --user as an engineer", EXIT_NOT_ALLOWED) from None
            if error.no_door:
                raise _Failure(f"{login.endpoint}: {error}") from None
            raise _Failure(str(error)) from None

    try:
        return asyncio.run(session())
    except LoginError as error:
        raise _Failure(str(error), error.exit_status) from None
    except (OSError, asyncio.TimeoutError, ConnectionError) as error:
        raise _Failure(f"lost the connection to {login.endpoint}: {error or type(error).__name__}", EXIT_NO_CONNECTION) from None


# -- showing ----------------------------------------------------------------------------------


def _show(args: argparse.Namespace, rows: list[dict[str, Any]]) -> None:
    from softplc.storage.audit.entry import AuditEntry, format_value

    stream = args.output.open("w", newline="", encoding="utf-8") if args.output else sys.stdout
    try:
        if args.format == "json":
            json.dump(rows, stream, indent=1, ensure_ascii=False, default=str)
            stream.write("\n")
        elif args.format == "csv":
            from softplc.storage.audit.queries import write_csv

            write_csv((AuditEntry.from_dict(row) for row in rows), stream)
        elif rows:
            from softplc.util.console import print_table

            table = [[format_shown(row["time"], milliseconds=True), row["source"], row["user"], row["peer"], _what(row),
                      format_value(row["old"]), format_value(row["new"]), _result(row)] for row in rows]
            print_table(table, HEADER, stream)
    finally:
        if args.output:
            stream.close()
    if args.output:
        print(f"wrote {plural(len(rows), 'audit entry', 'audit entries')} to {args.output}", file=sys.stderr)
    elif not rows:
        print("no audit entries match", file=sys.stderr)


def _what(row: dict[str, Any]) -> str:
    if row["kind"] == "write":
        return row["name"]
    from softplc.storage.audit.entry import format_value

    arguments = row["arguments"] if isinstance(row["arguments"], dict) else {}
    shown = [row["tag"]] if row["tag"] else []
    shown += [f"{key}={format_value(value)}" for key, value in arguments.items() if key not in ("tag", "value") or not row["tag"]]
    return " ".join([row["name"], *shown])


def _result(row: dict[str, Any]) -> str:
    if row["accepted"]:
        return "accepted"
    rule = "" if row["rule"] == "refused" else f"{row['rule']}: "  # a command's own reason says it all
    return f"refused: {rule}{row['detail']}" if row["detail"] else f"refused: {row['rule']}"
