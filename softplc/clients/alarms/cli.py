"""`softplc alarms list|ack|shelve|unshelve|comment|journal|out-of-service|in-service` against a running runtime.

Every subcommand calls the runtime's `alarms.*` commands through the OPC UA commands door
(softplc/clients/door_client.py), logged in with the options every client command shares
(softplc/clients/login.py: --endpoint or the plant's --config, --user, --password-stdin or
$SOFTPLC_PASSWORD, --security); the runtime checks the role, so a viewer may list and read the
journal but not acknowledge. Exit statuses, those of every OPC UA client command: 0 done, 1
refused by the runtime (its reason), 2 bad command line, 3 no connection, 4 not allowed (the
login refused, or the session's role may not).
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

from softplc.clients.login import Login, LoginError, Security, add_login_arguments, login_from_args
from softplc.util.timestamps import TIME_HELP, format_shown, parse_time

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_NO_CONNECTION, EXIT_NOT_ALLOWED = 0, 1, 2, 3, 4
# What each action needs, to say so when the runtime refuses a session's role.
NEEDS = {"alarms.acknowledge": "operator", "alarms.acknowledge_all": "operator", "alarms.shelve": "operator",
         "alarms.unshelve": "operator", "alarms.comment": "operator", "alarms.out_of_service": "engineer",
         "alarms.in_service": "engineer"}
EXAMPLES = ("Examples: softplc alarms list --state unacknowledged | SOFTPLC_PASSWORD=... softplc alarms ack t01_input_full "
            "--user otto | softplc alarms shelve r02_blocked --for 30min --reason 'robot in repair' --user otto | "
            "softplc alarms journal --since 8h --export csv > journal.csv | softplc alarms list --endpoint "
            "opc.tcp://plc7:4840/softplc/ --security SignAndEncrypt")
STATES = ("all", "annunciated", "active", "unacknowledged", "shelved", "suppressed", "out_of_service", "normal")
JOURNAL_PAGE = 1000  # rows per alarms.journal call


def add_commands(subparsers: Any) -> None:
    """Register `alarms` with the softplc command line."""
    alarms = subparsers.add_parser(
        "alarms", help="alarms of a running runtime: list, acknowledge, shelve, comment, journal",
        description="Look at and act on the alarms of a running softplc over OPC UA. Acting needs an operator "
        "(out-of-service: an engineer): give --user, and the password on stdin (--password-stdin), in "
        "$SOFTPLC_PASSWORD or at the prompt. Each subcommand takes the login options of every OPC UA client "
        "command (softplc alarms list --help). Exit statuses: 0 done, 1 refused, 2 bad command line, "
        "3 no connection, 4 not allowed.",
        epilog=EXAMPLES,
    )
    commands = alarms.add_subparsers(title="subcommands", metavar="SUBCOMMAND")
    listing = commands.add_parser("list", help="alarms and their states", epilog=EXAMPLES)
    listing.add_argument("--state", choices=STATES, default="annunciated", help="which alarms (default annunciated: those shown to the operator)")
    listing.add_argument("--name", metavar="PATTERN", help="only names matching PATTERN (* and ?)")
    listing.add_argument("--priority", choices=("low", "medium", "high", "critical"), help="only this priority and above")
    listing.add_argument("--format", choices=("table", "json"), default="table")
    listing.set_defaults(func=cmd_list)
    ack = commands.add_parser("ack", help="acknowledge alarms",
                              epilog="Examples: softplc alarms ack t01_input_full --comment 'pump checked' --user otto | "
                              "echo \"$PW\" | softplc alarms ack --all --user otto --password-stdin")
    ack.add_argument("alarm", nargs="*", help="alarm names (or --all)")
    ack.add_argument("--all", action="store_true", help="every alarm waiting for an acknowledgement")
    ack.add_argument("--comment", default="", help="a comment for the journal")
    ack.set_defaults(func=cmd_ack)
    shelve = commands.add_parser("shelve", help="shelve an alarm for a while, or until it returns to normal",
                                 epilog="Examples: softplc alarms shelve r02_blocked --for 30min --reason 'robot in repair' --user otto | "
                                 "softplc alarms shelve t01_input_full --one-shot --reason 'known' --user otto")
    shelve.add_argument("alarm")
    how = shelve.add_mutually_exclusive_group(required=True)
    how.add_argument("--for", dest="duration", metavar="DURATION", help="e.g. 30min, 2h (at most the plant's alarms.shelve_max)")
    how.add_argument("--one-shot", action="store_true", help="until it next returns to normal")
    shelve.add_argument("--reason", required=True, help="why (kept in the journal)")
    shelve.set_defaults(func=cmd_shelve)
    unshelve = commands.add_parser("unshelve", help="unshelve an alarm", epilog="Example: softplc alarms unshelve r02_blocked --user otto")
    unshelve.add_argument("alarm")
    unshelve.add_argument("--reason", default="")
    unshelve.set_defaults(func=cmd_unshelve)
    comment = commands.add_parser("comment", help="comment an alarm (kept in the journal)",
                                  epilog="Example: softplc alarms comment r02_blocked 'wheel ordered' --user otto")
    comment.add_argument("alarm")
    comment.add_argument("text")
    comment.set_defaults(func=cmd_comment)
    out = commands.add_parser("out-of-service", help="take an alarm out of service (engineer)",
                              epilog="Example: softplc alarms out-of-service t03_level_hi --reason 'sensor replaced' --user erin")
    out.add_argument("alarm")
    out.add_argument("--reason", required=True)
    out.set_defaults(func=cmd_out_of_service)
    back = commands.add_parser("in-service", help="return an alarm to service (engineer)",
                               epilog="Example: softplc alarms in-service t03_level_hi --user erin")
    back.add_argument("alarm")
    back.add_argument("--reason", default="")
    back.set_defaults(func=cmd_in_service)
    journal = commands.add_parser("journal", help="the journal of transitions and actions, newest first",
                                  description="The alarm journal, newest first. Times shown and typed are UTC: a time "
                                  "without a zone is read as UTC, whatever this computer's or the runtime's zone.",
                                  epilog="Examples: softplc alarms journal --since 8h | softplc alarms journal --alarm 't01_*' --by otto | "
                                  "softplc alarms journal --since 2026-11-24T08:00 --export csv --out journal.csv")
    journal.add_argument("--alarm", metavar="PATTERN", help="alarm name or pattern (* and ?)")
    journal.add_argument("--since", metavar="TIME", help=f"from TIME: {TIME_HELP}")
    journal.add_argument("--until", metavar="TIME", help="up to TIME, excluded (same forms)")
    journal.add_argument("--text", help="text in the message, comment or user")
    journal.add_argument("--by", dest="by_user", metavar="USER", help="actions of this user")
    journal.add_argument("--transition", action="append", default=[], help="e.g. activated, acknowledged, shelved (repeatable)")
    journal.add_argument("--limit", type=int, default=None, help="most rows (default 100 shown, every row exported)")
    journal.add_argument("--export", choices=("csv", "json"), help="write every matching row as CSV or JSON")
    journal.add_argument("--out", type=Path, metavar="FILE", help="with --export: write to FILE instead of stdout")
    journal.set_defaults(func=cmd_journal)
    for parser in (listing, ack, shelve, unshelve, comment, out, back, journal):
        _connection_options(parser)
    alarms.set_defaults(func=lambda args: (alarms.print_help(), EXIT_USAGE)[1])


def _connection_options(parser: argparse.ArgumentParser) -> None:
    add_login_arguments(parser, user_help="; an operator acknowledges, shelves and comments, an engineer takes out of service")
    # Until the login options were shared: --security MODE with --certificate FILE --key FILE (now MODE,CERT,KEY).
    parser.add_argument("--certificate", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--key", type=Path, help=argparse.SUPPRESS)


# -- subcommands ----------------------------------------------------------------------------------


def cmd_list(args: argparse.Namespace) -> int:
    arguments: dict[str, Any] = {"state": args.state}
    if args.name:
        arguments["name"] = args.name
    if args.priority:
        arguments["priority"] = args.priority
    status, alarms = _run(args, [("alarms.list", arguments)])
    if status != EXIT_OK:
        return status
    alarms = alarms[0]
    if args.format == "json":
        print(json.dumps(alarms, indent=2))
        return EXIT_OK
    from softplc.util.console import print_table

    rows = [[alarm["name"], alarm["state"], alarm["priority"], _when(alarm.get("since")), alarm["message"]] for alarm in alarms]
    if rows:
        print_table(rows, ("alarm", "state", "priority", "since", "message"))
    else:
        print(f"no alarms ({args.state})", file=sys.stderr)
    return EXIT_OK


def cmd_ack(args: argparse.Namespace) -> int:
    if args.all == bool(args.alarm):
        print("softplc alarms ack: name the alarms to acknowledge, or give --all (not both)", file=sys.stderr)
        return EXIT_USAGE
    if args.all:
        calls = [("alarms.acknowledge_all", {"comment": args.comment})]
    else:
        calls = [("alarms.acknowledge", {"alarm": name, "comment": args.comment}) for name in args.alarm]
    return _act(args, calls)


def cmd_shelve(args: argparse.Namespace) -> int:
    arguments: dict[str, Any] = {"alarm": args.alarm, "reason": args.reason}
    if args.one_shot:
        arguments["one_shot"] = True
    else:
        arguments["duration"] = args.duration
    return _act(args, [("alarms.shelve", arguments)])


def cmd_unshelve(args: argparse.Namespace) -> int:
    return _act(args, [("alarms.unshelve", {"alarm": args.alarm, "reason": args.reason})])


def cmd_comment(args: argparse.Namespace) -> int:
    return _act(args, [("alarms.comment", {"alarm": args.alarm, "comment": args.text})])


def cmd_out_of_service(args: argparse.Namespace) -> int:
    return _act(args, [("alarms.out_of_service", {"alarm": args.alarm, "reason": args.reason})])


def cmd_in_service(args: argparse.Namespace) -> int:
    return _act(args, [("alarms.in_service", {"alarm": args.alarm, "reason": args.reason})])


def cmd_journal(args: argparse.Namespace) -> int:
    try:
        query: dict[str, Any] = {key: value for key, value in (
            ("alarm", args.alarm), ("since", _time(args.since, "--since")), ("until", _time(args.until, "--until")),
            ("text", args.text), ("user", args.by_user), ("transition", args.transition or None)) if value}
    except ValueError as error:
        print(f"softplc alarms journal: {error}", file=sys.stderr)
        return EXIT_USAGE
    wanted = args.limit if args.limit is not None else (math.inf if args.export else 100)
    status, rows = _run(args, [], journal=(query, wanted))
    if status != EXIT_OK:
        return status
    if args.export:
        stream = args.out.open("w", newline="", encoding="utf-8") if args.out else sys.stdout
        try:
            if args.export == "json":
                json.dump(rows, stream, indent=2)
                stream.write("\n")
            else:
                from softplc.storage.alarm_journal import entries_from_dicts, write_csv

                write_csv(entries_from_dicts(rows), stream)
        finally:
            if args.out:
                stream.close()
        if args.out:
            print(f"wrote {len(rows)} journal rows to {args.out}", file=sys.stderr)
        return EXIT_OK
    from softplc.util.console import print_table

    table = [[_when(row["time"]), row["alarm"], row["transition"], row["state"], row["user"], row["comment"] or row["message"]] for row in rows]
    if table:
        print_table(table, ("time", "alarm", "transition", "state", "user", "comment / message"))
    else:
        print("no journal rows match", file=sys.stderr)
    return EXIT_OK


# -- calling the runtime --------------------------------------------------------------------------


def _act(args: argparse.Namespace, calls: list[tuple[str, dict[str, Any]]]) -> int:
    status, results = _run(args, calls)
    for result in results:
        print(result)
    return status


Journal = tuple[dict[str, Any], float]  # the alarms.journal query and how many rows are wanted


def _run(args: argparse.Namespace, calls: list[tuple[str, dict[str, Any]]], journal: Journal | None = None) -> tuple[int, list[Any]]:
    """Call the commands in one session; (exit status, results); refusals and failures are printed."""
    if getattr(args, "verbose", 0) < 2:
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)  # this command reports what asyncua would warn about
    try:
        _old_certificate_options(args)
        login = login_from_args(args)
        return asyncio.run(_session(login, calls, journal))
    except LoginError as error:
        print(f"softplc alarms: {error}", file=sys.stderr)
        return error.exit_status, []


async def _session(login: Login, calls: list[tuple[str, dict[str, Any]]], journal: Journal | None) -> tuple[int, list[Any]]:
    from softplc.clients.door_client import CommandError, call_command, call_pages
    from softplc.clients.session import NotSoftplc, open_live_session

    results: list[Any] = []
    status = EXIT_OK
    try:
        async with open_live_session(login) as live:
            for name, arguments in calls:
                try:
                    results.append(await call_command(live.client, live.ns, name, arguments))
                except CommandError as error:
                    if error.no_door:
                        raise
                    status = max(status, EXIT_NOT_ALLOWED if error.not_allowed else EXIT_REFUSED)
                    print(f"softplc alarms: refused: {_refusal(error, login.user)}", file=sys.stderr)
            if journal is not None:
                query, wanted = journal
                results += await call_pages(live.client, live.ns, "alarms.journal", query, wanted, JOURNAL_PAGE)
        return status, results
    except NotSoftplc as error:
        print(f"softplc alarms: {login.endpoint}: {error}", file=sys.stderr)
        return EXIT_NO_CONNECTION, []
    except CommandError as error:  # no door, or a page of the journal refused
        reason = f"{login.endpoint}: {error}" if error.no_door else f"refused: {_refusal(error, login.user)}"
        print(f"softplc alarms: {reason}", file=sys.stderr)
        return EXIT_NOT_ALLOWED if error.not_allowed else EXIT_REFUSED, []
    except (OSError, asyncio.TimeoutError, ConnectionError) as error:
        print(f"softplc alarms: lost the connection to {login.endpoint}: {error or type(error).__name__}", file=sys.stderr)
        return EXIT_NO_CONNECTION, []


def _refusal(error: Exception, user: str | None) -> str:
    name = getattr(error, "name", "")
    if not getattr(error, "not_allowed", False):
        return str(error)
    who = f"user {user!r}" if user else "an anonymous session (a viewer)"
    needs = NEEDS.get(name, "another")
    return (f"{name} needs the {needs} role{' or higher' if needs == 'operator' else ''}, and {who} does not have it; "
            f"log in with --user as such a user (softplc users add NAME --role {needs} on the runtime's machine)")


def _old_certificate_options(args: argparse.Namespace) -> None:
    """--security MODE --certificate CERT --key KEY (the former spelling) as --security MODE,CERT,KEY."""
    if args.certificate is None and args.key is None:
        return
    if args.certificate is None or args.key is None:
        raise LoginError("give --certificate and --key together (better: --security MODE,CERT,KEY)", "usage")
    mode = args.security.mode if args.security is not None else "None"
    if mode == "None":
        raise LoginError("--certificate and --key are for --security Sign or SignAndEncrypt", "usage")
    try:
        args.security = Security.parse(f"{mode},{args.certificate},{args.key}")
    except ValueError as error:
        raise LoginError(str(error), "usage") from None
    print("softplc alarms: note: --certificate and --key are deprecated: write --security MODE,CERT,KEY", file=sys.stderr)


def _time(text: str | None, option: str) -> float | None:
    """Epoch seconds of an ISO time (UTC unless it gives a zone), or of now minus a duration ('8h', '30min')."""
    if not text:
        return None
    try:
        return parse_time(text, time.time())
    except ValueError as error:
        raise ValueError(f"{option} {error}") from None


def _when(seconds: Any) -> str:
    if not isinstance(seconds, (int, float)) or not seconds:
        return ""
    return format_shown(seconds)
