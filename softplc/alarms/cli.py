"""`softplc alarms list|ack|shelve|unshelve|comment|journal|out-of-service|in-service` against a running runtime.

Every subcommand calls the runtime's `alarms.*` commands over OPC UA (`Objects/Commands`), logged
in as `--user` (password from $SOFTPLC_PASSWORD, or asked for on a terminal); the runtime checks
the role, so a viewer may list and read the journal but not acknowledge.
"""

from __future__ import annotations

import argparse
import asyncio
import getpass
import json
import math
import os
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/softplc/"
PASSWORD_VARIABLE = "SOFTPLC_PASSWORD"
# What each action needs, to say so when the runtime refuses a session's role.
NEEDS = {"alarms.acknowledge": "operator", "alarms.acknowledge_all": "operator", "alarms.shelve": "operator",
         "alarms.unshelve": "operator", "alarms.comment": "operator", "alarms.out_of_service": "engineer",
         "alarms.in_service": "engineer"}
STATES = ("all", "annunciated", "active", "unacknowledged", "shelved", "suppressed", "out_of_service", "normal")


def add_commands(subparsers: Any) -> None:
    """Register `alarms` with the softplc command line."""
    alarms = subparsers.add_parser(
        "alarms", help="alarms of a running runtime: list, acknowledge, shelve, comment, journal",
        description="Look at and act on the alarms of a running softplc over OPC UA. Acting needs an operator "
        "(out-of-service: an engineer); give --user and the password in $SOFTPLC_PASSWORD.",
        epilog="Examples: softplc alarms list --state unacknowledged | SOFTPLC_PASSWORD=... softplc alarms ack t01_input_full "
        "--user otto | softplc alarms shelve r02_blocked --for 30min --reason 'robot in repair' --user otto | "
        "softplc alarms journal --since 8h --export csv > journal.csv",
    )
    commands = alarms.add_subparsers(title="subcommands", metavar="SUBCOMMAND")
    listing = commands.add_parser("list", help="alarms and their states")
    listing.add_argument("--state", choices=STATES, default="annunciated", help="which alarms (default annunciated: those shown to the operator)")
    listing.add_argument("--name", metavar="PATTERN", help="only names matching PATTERN (* and ?)")
    listing.add_argument("--priority", choices=("low", "medium", "high", "critical"), help="only this priority and above")
    listing.add_argument("--format", choices=("table", "json"), default="table")
    listing.set_defaults(func=cmd_list)
    ack = commands.add_parser("ack", help="acknowledge alarms")
    ack.add_argument("alarm", nargs="*", help="alarm names (or --all)")
    ack.add_argument("--all", action="store_true", help="every alarm waiting for an acknowledgement")
    ack.add_argument("--comment", default="", help="a comment for the journal")
    ack.set_defaults(func=cmd_ack)
    shelve = commands.add_parser("shelve", help="shelve an alarm for a while, or until it returns to normal")
    shelve.add_argument("alarm")
    how = shelve.add_mutually_exclusive_group(required=True)
    how.add_argument("--for", dest="duration", metavar="DURATION", help="e.g. 30min, 2h (at most the plant's alarms.shelve_max)")
    how.add_argument("--one-shot", action="store_true", help="until it next returns to normal")
    shelve.add_argument("--reason", required=True, help="why (kept in the journal)")
    shelve.set_defaults(func=cmd_shelve)
    unshelve = commands.add_parser("unshelve", help="unshelve an alarm")
    unshelve.add_argument("alarm")
    unshelve.add_argument("--reason", default="")
    unshelve.set_defaults(func=cmd_unshelve)
    comment = commands.add_parser("comment", help="comment an alarm (kept in the journal)")
    comment.add_argument("alarm")
    comment.add_argument("text")
    comment.set_defaults(func=cmd_comment)
    out = commands.add_parser("out-of-service", help="take an alarm out of service (engineer)")
    out.add_argument("alarm")
    out.add_argument("--reason", required=True)
    out.set_defaults(func=cmd_out_of_service)
    back = commands.add_parser("in-service", help="return an alarm to service (engineer)")
    back.add_argument("alarm")
    back.add_argument("--reason", default="")
    back.set_defaults(func=cmd_in_service)
    journal = commands.add_parser("journal", help="the journal of transitions and actions, newest first")
    journal.add_argument("--alarm", metavar="PATTERN", help="alarm name or pattern (* and ?)")
    journal.add_argument("--since", metavar="TIME", help="ISO time (2026-11-24T08:00) or how long ago (8h, 30min)")
    journal.add_argument("--until", metavar="TIME", help="ISO time or how long ago")
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
    group = parser.add_argument_group("connection")
    group.add_argument("--endpoint", metavar="URL", help=f"the runtime's OPC UA endpoint (default: servers.opcua.endpoint of --config, else {DEFAULT_ENDPOINT})")
    group.add_argument("--config", default="tagdb.yaml", help="plant configuration to take the endpoint from (default tagdb.yaml, if present)")
    group.add_argument("--user", metavar="USER",
                       help=f"log in as USER (password from ${PASSWORD_VARIABLE}, or asked); default anonymous, a viewer")
    group.add_argument("--security", choices=("None", "Sign", "SignAndEncrypt"), default="None",
                       help="Basic256Sha256 Sign or SignAndEncrypt (a client certificate is made in ~/.softplc/cli-client; "
                       "the server must trust it: softplc opcua trust FINGERPRINT)")
    group.add_argument("--certificate", type=Path, metavar="DER", help="client certificate for --security (with --key)")
    group.add_argument("--key", type=Path, metavar="PEM", help="private key of --certificate")
    group.add_argument("--namespace", default="urn:softplc:tags", help="namespace URI of the runtime's nodes (default urn:softplc:tags)")


# -- subcommands ----------------------------------------------------------------------------------


def cmd_list(args: argparse.Namespace) -> int:
    arguments: dict[str, Any] = {"state": args.state}
    if args.name:
        arguments["name"] = args.name
    if args.priority:
        arguments["priority"] = args.priority
    ok, alarms = _run(args, [("alarms.list", arguments)])
    if not ok:
        return EXIT_FAILURE
    alarms = alarms[0]
    if args.format == "json":
        print(json.dumps(alarms, indent=2))
        return EXIT_OK
    from softplc.console import print_table

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
    ok, rows = _run(args, [], journal=(query, wanted))
    if not ok:
        return EXIT_FAILURE
    if args.export:
        stream = args.out.open("w", newline="", encoding="utf-8") if args.out else sys.stdout
        try:
            if args.export == "json":
                json.dump(rows, stream, indent=2)
                stream.write("\n")
            else:
                from softplc.alarms.journal import entries_from_dicts, write_csv

                write_csv(entries_from_dicts(rows), stream)
        finally:
            if args.out:
                stream.close()
        if args.out:
            print(f"wrote {len(rows)} journal rows to {args.out}", file=sys.stderr)
        return EXIT_OK
    from softplc.console import print_table

    table = [[_when(row["time"]), row["alarm"], row["transition"], row["state"], row["user"], row["comment"] or row["message"]] for row in rows]
    if table:
        print_table(table, ("time", "alarm", "transition", "state", "user", "comment / message"))
    else:
        print("no journal rows match", file=sys.stderr)
    return EXIT_OK


# -- calling the runtime --------------------------------------------------------------------------


def _act(args: argparse.Namespace, calls: list[tuple[str, dict[str, Any]]]) -> int:
    ok, results = _run(args, calls)
    for result in results:
        print(result)
    return EXIT_OK if ok else EXIT_FAILURE


def _run(args: argparse.Namespace, calls: list[tuple[str, dict[str, Any]]], journal: tuple[dict[str, Any], float] | None = None) -> tuple[bool, list[Any]]:
    """Call the commands in one session; (all carried out, results); refusals are printed."""
    from softplc.alarms.remote import RemoteCommands, RemoteError, RemoteRefused

    endpoint = args.endpoint or _configured_endpoint(args.config)
    if (args.certificate is None) != (args.key is None):
        print("softplc alarms: give --certificate and --key together", file=sys.stderr)
        return False, []
    password = _password(args.user)
    security = "None" if args.security == "None" else f"Basic256Sha256_{args.security}"

    async def session() -> tuple[bool, list[Any]]:
        results: list[Any] = []
        ok = True
        async with RemoteCommands(endpoint, user=args.user, password=password, security=security, certificate=args.certificate,
                                  private_key=args.key, namespace=args.namespace) as remote:
            for name, arguments in calls:
                try:
                    results.append(await remote.call(name, arguments))
                except RemoteRefused as refused:
                    ok = False
                    print(f"softplc alarms: refused: {_refusal(refused, name, args.user)}", file=sys.stderr)
            if journal is not None:
                query, wanted = journal
                while len(results) < wanted:
                    page = await remote.call("alarms.journal", {**query, "limit": int(min(1000, wanted - len(results))), "offset": len(results)})
                    results.extend(page)
                    if len(page) < 1000:
                        break
        return ok, results

    try:
        return asyncio.run(session())
    except RemoteRefused as refused:  # the journal's pages
        print(f"softplc alarms: refused: {_refusal(refused, 'alarms.journal', args.user)}", file=sys.stderr)
    except RemoteError as error:
        print(f"softplc alarms: {error}", file=sys.stderr)
    return False, []


def _refusal(refused: Exception, name: str, user: str | None) -> str:
    if not getattr(refused, "by_role", False):
        return str(refused)
    who = f"user {user!r}" if user else "an anonymous session (a viewer)"
    needs = NEEDS.get(name, "another")
    return (f"{name} needs the {needs} role{' or higher' if needs == 'operator' else ''}, and {who} does not have it; "
            f"log in with --user as such a user (softplc users add NAME --role {needs} on the runtime's machine)")


def _password(user: str | None) -> str | None:
    if user is None:
        return None
    password = os.environ.get(PASSWORD_VARIABLE)
    if password is None and sys.stdin.isatty():
        password = getpass.getpass(f"OPC UA password of {user}: ")
    return password or ""


def _configured_endpoint(config: str) -> str:
    path = Path(config)
    if not path.is_file():
        return DEFAULT_ENDPOINT
    from softplc.yamlsource import ConfigError, load_yaml

    try:
        data, _ = load_yaml(path)
    except (ConfigError, OSError):
        return DEFAULT_ENDPOINT
    servers = data.get("servers") if isinstance(data, dict) else None
    opcua = servers.get("opcua") if isinstance(servers, dict) else None
    endpoint = opcua.get("endpoint") if isinstance(opcua, dict) else None
    if not isinstance(endpoint, str):
        return DEFAULT_ENDPOINT
    for wildcard in ("0.0.0.0", "[::]"):  # a server listening everywhere is reached on loopback here
        endpoint = endpoint.replace(f"//{wildcard}:", "//127.0.0.1:")
    return endpoint


def _time(text: str | None, option: str) -> float | None:
    """Epoch seconds of an ISO time, or of now minus a duration ('8h', '30min')."""
    if not text:
        return None
    from softplc.durations import parse_duration

    try:
        return datetime.now().timestamp() - parse_duration(text)
    except ValueError:
        pass
    try:
        return datetime.fromisoformat(text).timestamp()
    except ValueError:
        raise ValueError(f"{option} {text!r}: write an ISO time such as 2026-11-24T08:00, or how long ago such as 8h or 30min") from None


def _when(seconds: Any) -> str:
    if not isinstance(seconds, (int, float)) or not seconds:
        return ""
    return datetime.fromtimestamp(seconds).isoformat(sep=" ", timespec="seconds")
