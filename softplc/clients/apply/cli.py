"""`softplc apply`: an online change of a running plant, from this machine or another.

It logs in over OPC UA as an engineer, with the options every client command shares
(softplc/clients/login.py), and calls the runtime's `programs.apply` command through the server's
door to the commands (softplc/clients/door_client.py). The runtime re-reads the file it was
started with and checks it (softplc/engine/online_change/change.py); this command prints what it answers.
`--config` (the plant's configuration, default tagdb.yaml here) only says where the plant serves.

    softplc apply --user erin                     # password from a prompt, $SOFTPLC_PASSWORD or --password-stdin
    softplc apply --check --user erin             # show the differences, apply nothing
    softplc apply --endpoint opc.tcp://plc7:4840/softplc/ --user erin --security SignAndEncrypt

Exit statuses, those of every OPC UA client command (docs/operations.md) and one of its own:
0 applied (or checked, or nothing to apply); 1 refused by the runtime for another reason; 2 a bad
command line, or the file or a program has problems (`FILE:LINE:COL: message` each); 3 no
connection; 4 not allowed: the login was refused, or the user's role may not apply online
changes (an engineer's may); 5 the change needs a restart of the runtime (the reasons and the
differences are printed). Until the login options were shared, 3 meant "needs a restart".
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import re
import sys
from typing import Any

from softplc.clients.login import Login, LoginError, add_login_arguments, login_from_args

EXIT_OK, EXIT_REFUSED, EXIT_PROBLEMS, EXIT_NO_CONNECTION, EXIT_NOT_ALLOWED, EXIT_RESTART = 0, 1, 2, 3, 4, 5
TIMEOUT = 75.0  # seconds: the runtime gives a check 60 s before it refuses the change


class ApplyError(Exception):
    """Why the command could not be called, and the exit status that says so."""

    def __init__(self, message: str, status: int = EXIT_REFUSED, *, runtime_words: bool = False) -> None:
        super().__init__(message)
        self.status = status
        self.runtime_words = runtime_words  # the runtime's refusal, printed as it is


def add_commands(subparsers: Any) -> None:
    """Register `apply` with the softplc command line."""
    parser = subparsers.add_parser(
        "apply",
        help="apply an online change to a running plant (engineer)",
        description="Ask a running softplc to re-read its configuration and apply the changes of its programs "
        "(code, params, bind, on_fault, restart, enabled) at a scan boundary, without stopping the plant. "
        "Nothing is applied if anything is wrong; changes that need a restart are refused with the reason. "
        "Exit statuses: 0 applied, 1 refused, 2 problems in the file (or a bad command line), 3 no connection, "
        "4 not allowed, 5 needs a restart.",
        epilog="Examples: softplc apply --user erin | softplc apply --check --user erin | echo \"$PW\" | softplc apply "
        "--endpoint opc.tcp://plc7:4840/softplc/ --user erin --password-stdin --security SignAndEncrypt",
    )
    # The former spelling `softplc apply CONFIG` still works; --config is the shared option's name.
    parser.add_argument("config_file", nargs="?", metavar="CONFIG", help=argparse.SUPPRESS)
    parser.add_argument("--check", action="store_true", help="check and show the differences, apply nothing")
    add_login_arguments(parser, timeout_default=TIMEOUT, user_help="; an engineer may apply")
    parser.set_defaults(func=cmd_apply)


def cmd_apply(args: argparse.Namespace) -> int:
    if getattr(args, "verbose", 0) < 2:
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)  # this command reports what asyncua would warn about
    if args.config_file is not None:
        if args.config is not None and args.config != args.config_file:
            print(f"softplc apply: two configurations: {args.config_file} and --config {args.config}", file=sys.stderr)
            return EXIT_PROBLEMS
        args.config = args.config_file
    try:
        login = login_from_args(args)
        result = asyncio.run(apply(login, check=args.check))
    except LoginError as error:
        print(f"softplc apply: {error}", file=sys.stderr)
        return error.exit_status
    except ApplyError as error:
        print(error if error.runtime_words else f"softplc apply: {error}", file=sys.stderr)
        return error.status
    print(report(result or {}))
    return EXIT_OK


async def apply(login: Login, *, check: bool) -> Any:
    """Call programs.apply on the runtime `login` reaches; its result, or ApplyError with the status."""
    from softplc.clients.door_client import CommandError, call_command
    from softplc.clients.session import NotSoftplc, open_live_session

    try:
        async with open_live_session(login) as live:
            return await call_command(live.client, live.ns, "programs.apply", {"check": True} if check else {})
    except NotSoftplc as error:
        raise ApplyError(f"{login.endpoint}: {error}", EXIT_NO_CONNECTION) from None
    except CommandError as error:
        if error.not_allowed:
            who = f"user {login.user}" if login.user else "an anonymous session"
            raise ApplyError(f"{who} may not apply online changes: log in as an engineer (--user)", EXIT_NOT_ALLOWED) from None
        if error.no_door:
            raise ApplyError(f"{login.endpoint}: {error} (an older softplc?)") from None
        first = str(error).split("\n", 1)[0]
        # "1 problem:", "2 problems:" ("problem(s):" from runtimes before 2026-11-27)
        status = EXIT_PROBLEMS if re.search(r" \d+ problem(s|\(s\))?:", first) else EXIT_RESTART if "need a restart" in first else EXIT_REFUSED
        raise ApplyError(str(error), status, runtime_words=True) from None
    except (OSError, asyncio.TimeoutError, ConnectionError) as error:
        raise ApplyError(f"lost the connection to {login.endpoint}: {error or type(error).__name__}", EXIT_NO_CONNECTION) from None


def report(result: dict[str, Any]) -> str:
    """What the runtime answered, for the engineer."""
    lines = [str(result.get("summary", ""))]
    lines += [f"  {line}" for line in result.get("changes", [])]
    for program in result.get("programs", []):
        carried = program.get("carried_over")
        if program.get("new_program"):
            kept = "nothing" if not carried else ", ".join(carried) if carried is not None else "(the program's carry_over() did not say)"
            lines.append(f"  program {program['name']}: new version {program['state']}, state carried over: {kept}")
    return "\n".join(line for line in lines if line)
