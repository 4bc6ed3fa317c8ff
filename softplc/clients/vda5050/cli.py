"""`softplc vda5050 vehicles|factsheets|orders|action` against a running plant, over OPC UA's commands door.

Each subcommand calls the runtime's `vda5050.*` queries and commands (softplc/adapters/vda5050/commands.py)
through softplc/clients/door_client.py, logged in with the options every client command shares
(softplc/clients/login.py). Sending an instant action needs the engineer role; the runtime checks
it and audits the call like every command. Exit statuses: 0 done, 1 refused by the runtime, 2 bad
command line, 3 no connection, 4 not allowed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
from typing import Any

from softplc.clients.login import Login, LoginError, add_login_arguments, login_from_args

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_NO_CONNECTION, EXIT_NOT_ALLOWED = 0, 1, 2, 3, 4
ACTIONS = ("startPause", "stopPause", "cancelOrder", "initPosition", "factsheetRequest", "stateRequest")
EXAMPLES = ("Examples: softplc vda5050 vehicles | softplc vda5050 orders --format json | softplc vda5050 factsheets | "
            "SOFTPLC_PASSWORD=... softplc vda5050 action r04 startPause --user erna | "
            "softplc vda5050 action r04 initPosition --param x=3.5 --param y=6.6 --param theta=0 --user erna")


def add_commands(subparsers: Any) -> None:
    """Register `vda5050` with the softplc command line."""
    vda = subparsers.add_parser(
        "vda5050", help="VDA 5050 vehicles of a running plant: list them, their factsheets and orders; send instant actions",
        description="Look at the VDA 5050 vehicles a running softplc drives, over OPC UA, and send them instant actions "
        "(engineer role; audited). Each subcommand takes the login options of every OPC UA client command. "
        "Exit statuses: 0 done, 1 refused, 2 bad command line, 3 no connection, 4 not allowed.",
        epilog=EXAMPLES,
    )
    commands = vda.add_subparsers(title="subcommands", metavar="SUBCOMMAND")
    parsers = []
    for name, help_text, query in (("vehicles", "every vehicle: connection, liveness, order, errors, battery", "vda5050.vehicles"),
                                   ("factsheets", "each vehicle's factsheet and how it differs from robots.yaml", "vda5050.factsheets"),
                                   ("orders", "each vehicle's order: base (released) and horizon", "vda5050.orders")):
        parser = commands.add_parser(name, help=help_text, epilog=EXAMPLES)
        parser.add_argument("--format", choices=("table", "json"), default="table")
        parser.set_defaults(func=cmd_query, query=query, kind=name)
        parsers.append(parser)
    send = commands.add_parser("action", help="send an instant action to a vehicle (engineer)", epilog=EXAMPLES)
    send.add_argument("robot", help="the vehicle's robot id, e.g. r04")
    send.add_argument("action", choices=ACTIONS)
    send.add_argument("--param", action="append", default=[], metavar="KEY=VALUE", help="an action parameter (numbers stay numbers)")
    send.set_defaults(func=cmd_action)
    parsers.append(send)
    for parser in parsers:
        add_login_arguments(parser, user_help="; sending an instant action needs an engineer")
    vda.set_defaults(func=lambda args: (vda.print_help(), EXIT_USAGE)[1])


def cmd_query(args: argparse.Namespace) -> int:
    status, results = _run(args, [(args.query, {})])
    if status != EXIT_OK:
        return status
    rows = results[0]
    if args.format == "json":
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    from softplc.util.console import print_table

    if args.kind == "vehicles":
        table = [[row["robot"], f"{row['manufacturer']}/{row['serial_number']}", "yes" if row["alive"] else "LOST", row["connection"],
                  row["order"] or "-", " ".join(row["base"]) or "-", " ".join(row["horizon"]) or "-",
                  "-" if row["battery"] is None else f"{row['battery']:.0f} %", row["waiting"] or row["errors"] or "-"] for row in rows]
        header = ("robot", "vehicle", "alive", "connection", "order", "base", "horizon", "battery", "waiting / errors")
    elif args.kind == "factsheets":
        table = []
        for row in rows:
            sheet = row["factsheet"] or {}
            table.append([row["robot"], sheet.get("series_name", "(none yet)"), _number(sheet.get("length_mm")), _number(sheet.get("width_mm")),
                          _number(sheet.get("max_linear_speed")), _number(sheet.get("max_load_mass")), "; ".join(row["differences"]) or "-"])
        header = ("robot", "series", "length mm", "width mm", "speed m/s", "load", "differs from robots.yaml (which wins)")
    else:
        table = [[row["robot"], f"{row['order_id']}/{row['order_update_id']}", "yes" if row["acknowledged"] else "no",
                  " ".join(row["route"][: row["released"] + 1]), " ".join(row["route"][row["released"] + 1:]) or "-"] for row in rows]
        header = ("robot", "order", "acknowledged", "base", "horizon")
    if table:
        print_table(table, header)
    else:
        print(f"no {args.kind}", file=sys.stderr)
    return EXIT_OK


def cmd_action(args: argparse.Namespace) -> int:
    parameters: dict[str, Any] = {}
    for item in args.param:
        key, sep, text = item.partition("=")
        if not sep or not key:
            print(f"softplc vda5050 action: --param {item!r}: write KEY=VALUE", file=sys.stderr)
            return EXIT_USAGE
        try:
            parameters[key] = float(text) if text.strip().lstrip("-").replace(".", "", 1).isdigit() else text
        except ValueError:
            parameters[key] = text
    status, results = _run(args, [("vda5050.instant_action", {"robot": args.robot, "action": args.action, "parameters": parameters})])
    for result in results:
        print(f"sent {result['action']} to {result['robot']} (actionId {result['action_id']})")
    return status


def _number(value: Any) -> str:
    return "-" if value is None else f"{value:g}"


def _run(args: argparse.Namespace, calls: list[tuple[str, dict[str, Any]]]) -> tuple[int, list[Any]]:
    if getattr(args, "verbose", 0) < 2:
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)
    try:
        login = login_from_args(args)
        return asyncio.run(_session(login, calls))
    except LoginError as error:
        print(f"softplc vda5050: {error}", file=sys.stderr)
        return error.exit_status, []


async def _session(login: Login, calls: list[tuple[str, dict[str, Any]]]) -> tuple[int, list[Any]]:
    from softplc.clients.door_client import CommandError, call_command
    from softplc.clients.session import NotSoftplc, open_live_session

    results: list[Any] = []
    try:
        async with open_live_session(login) as live:
            for name, arguments in calls:
                results.append(await call_command(live.client, live.ns, name, arguments))
        return EXIT_OK, results
    except NotSoftplc as error:
        print(f"softplc vda5050: {login.endpoint}: {error}", file=sys.stderr)
        return EXIT_NO_CONNECTION, []
    except CommandError as error:
        if error.not_allowed:
            who = f"user {login.user!r}" if login.user else "an anonymous session"
            print(f"softplc vda5050: refused: {error.name} needs the engineer role, and {who} does not have it", file=sys.stderr)
            return EXIT_NOT_ALLOWED, []
        if "no such command" in str(error) or error.no_door:
            print(f"softplc vda5050: {login.endpoint}: this plant drives no VDA 5050 vehicles (no vda5050: section): {error}", file=sys.stderr)
            return EXIT_REFUSED, []
        print(f"softplc vda5050: refused: {error}", file=sys.stderr)
        return EXIT_REFUSED, []
    except (OSError, asyncio.TimeoutError, ConnectionError) as error:
        print(f"softplc vda5050: lost the connection to {login.endpoint}: {error or type(error).__name__}", file=sys.stderr)
        return EXIT_NO_CONNECTION, []
