"""`softplc read | write | watch | forces | force | unforce`: a running plant from a terminal, over OPC UA.

They log in with the options every OPC UA client command shares (softplc/clients/login.py), so they
work from another machine as well as this one. Exit statuses:

    0  done
    1  refused by a tag's rule (unknown tag, type, range, read-only, forced), or a value that does not parse;
       a command the runtime refused (e.g. unforce of a tag that is not forced)
    2  bad command line
    3  no connection: nothing answers at the endpoint, or the server went away (watch)
    4  not allowed: the login was refused (user, password, certificate), or the session's role may not
       write (a viewer) or force (anyone but an engineer)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from softplc.clients.login import LoginError, add_login_arguments, login_from_args

if TYPE_CHECKING:  # asyncua is imported when a command runs: `softplc --help` must not load it
    from softplc.clients.session import LiveSession

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_NO_CONNECTION, EXIT_NOT_ALLOWED = 0, 1, 2, 3, 4
EXAMPLES = "softplc read t01_iBL t01_qSL | softplc write t01_iFr=45 --user alice | softplc watch 't01_*' 'r0?_xpos'"


def add_commands(subparsers: Any) -> None:
    """Register read, write, watch, forces, force and unforce with the softplc command line."""
    read = subparsers.add_parser(
        "read", help="read tags of a running plant (OPC UA)",
        description="Read the current value, quality, forced mark (F) and time of last change of each TAG "
        "(or every tag matching a glob such as 't01_*') from a running softplc.", epilog=f"Examples: {EXAMPLES}",
    )
    read.add_argument("tags", nargs="+", metavar="TAG", help="tag names or globs")
    read.add_argument("--format", choices=("table", "json"), default="table")
    add_login_arguments(read)
    read.set_defaults(func=cmd_read)

    write = subparsers.add_parser(
        "write", help="write tags of a running plant (OPC UA)",
        description="Write each TAG=VALUE in one request. VALUE is typed as text and parsed by the tag's type "
        "(true/false, 42, 0.5, text). Each item is validated by the runtime like any client's write: a refused "
        "one says the rule it broke; if a value does not parse, nothing is written.",
        epilog="Examples: softplc write t01_iFr=45 --user alice | softplc write r01_xgoal=3.5 r01_ygoal=7.5 --user alice",
    )
    write.add_argument("assignments", nargs="+", metavar="TAG=VALUE")
    add_login_arguments(write)
    write.set_defaults(func=cmd_write)

    watch = subparsers.add_parser(
        "watch", help="watch tags of a running plant, updating in place (OPC UA subscription)",
        description="Show the tags matching each PATTERN (a name or a glob) in a table that updates in place as "
        "the server pushes changes: value, quality, F for a forced tag, time of the change (UTC). Piped to a "
        "file, it prints one line per change. Ctrl-C stops it; it also stops, saying so, when the server goes away.",
        epilog="Examples: softplc watch 't01_*' | softplc watch 'r0?_*pos' _sys.state --interval 500",
    )
    watch.add_argument("patterns", nargs="+", metavar="PATTERN", help="tag names or globs (quote them for the shell)")
    watch.add_argument("--interval", type=_milliseconds, default=100.0, metavar="MS",
                       help="the subscription's publishing interval (default 100 ms)")
    add_login_arguments(watch)
    watch.set_defaults(func=cmd_watch)

    forces = subparsers.add_parser(
        "forces", help="list the forced tags of a running plant (OPC UA)",
        description="List every forced tag: its forced value, since when and who forced it. Forced tags also "
        "carry the OPC UA StatusCode GoodLocalOverride, and show F in read and watch.",
        epilog="Examples: softplc forces | softplc forces --format json --config /srv/line2/tagdb.yaml",
    )
    forces.add_argument("--format", choices=("table", "json"), default="table")
    add_login_arguments(forces)
    forces.set_defaults(func=cmd_forces)

    force = subparsers.add_parser(
        "force", help="force tags of a running plant (engineer role)",
        description="Force each TAG to VALUE (parsed by the tag's type) from the next scan cycle: programs read "
        "the forced value, their writes to the tag and clients' writes are refused or dropped, every protocol "
        "shows it (CODESYS semantics, docs/runtime.md). Forces are not retained across a restart.",
        epilog="Examples: softplc force t01_iFr=0 --user eng | softplc unforce t01_iFr --user eng",
    )
    force.add_argument("assignments", nargs="+", metavar="TAG=VALUE")
    add_login_arguments(force)
    force.set_defaults(func=cmd_force)

    unforce = subparsers.add_parser(
        "unforce", help="release forced tags of a running plant (engineer role)",
        description="Release each forced TAG from the next scan cycle. It keeps the forced value until its "
        "owner (a program, a driver, a client) writes it again; with --restore it goes back to the value it had "
        "when it was forced.",
        epilog="Examples: softplc unforce t01_iFr --user eng | softplc unforce r01_xgoal r01_ygoal --restore --user eng",
    )
    unforce.add_argument("tags", nargs="+", metavar="TAG")
    unforce.add_argument("--restore", action="store_true", help="put back the value the tag had before the force")
    add_login_arguments(unforce)
    unforce.set_defaults(func=cmd_unforce)


def _milliseconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of milliseconds") from None
    if not 0 <= value <= 60_000:
        raise argparse.ArgumentTypeError(f"{text} is out of range: 0 to 60000 ms")
    return value


def _fail(command: str, message: str, status: int) -> int:
    print(f"softplc {command}: {message}", file=sys.stderr)
    return status


def _run(command: str, args: argparse.Namespace, body: Callable[[LiveSession], Awaitable[int]]) -> int:
    """Log in, run `body` on a session, log out; every failure becomes a message and an exit status."""
    if getattr(args, "verbose", 0) < 2:
        # asyncua warns about what this command reports itself (a refused login, a lost server) and
        # about a revised session timeout; -vv shows everything.
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)
    try:
        login = login_from_args(args)
    except LoginError as error:
        return _fail(command, str(error), error.exit_status)

    args.login = login  # a body that follows a redundant pair's active opens sessions of its own

    async def session() -> int:
        from softplc.clients.session import NotSoftplc, UnknownTags, open_live_session

        try:
            async with open_live_session(login) as live:
                return await body(live)
        except UnknownTags as error:
            return _fail(command, str(error), EXIT_REFUSED)
        except NotSoftplc as error:
            return _fail(command, f"{login.endpoint}: {error}", EXIT_NO_CONNECTION)

    try:
        return asyncio.run(session())
    except LoginError as error:
        return _fail(command, str(error), error.exit_status)
    except (OSError, asyncio.TimeoutError, ConnectionError) as error:
        return _fail(command, f"lost the connection to {login.endpoint}: {error or type(error).__name__}", EXIT_NO_CONNECTION)


def cmd_read(args: argparse.Namespace) -> int:
    async def body(live: LiveSession) -> int:
        from softplc.clients.tags.table import READING_HEADER, reading_json, reading_row, table_lines

        tags = await live.match(args.tags)
        readings = await live.read(tags)
        if args.format == "json":
            print(json.dumps([reading_json(reading) for reading in readings], indent=2))
        else:
            print("\n".join(table_lines([reading_row(r, r.tag) for r in readings], READING_HEADER)))
        return EXIT_OK

    return _run("read", args, body)


def cmd_write(args: argparse.Namespace) -> int:
    from softplc.clients.tags.writing import parse_assignments

    try:
        assignments = parse_assignments(args.assignments)
    except ValueError as error:
        return _fail("write", str(error), EXIT_USAGE)

    async def body(live: LiveSession) -> int:
        from softplc.clients.tags.writing import write_tags
        from softplc.core.tagdb import Rule

        outcomes, sent = await write_tags(live, assignments)
        if len(args.login.endpoints) > 1 and any(o.rule is Rule.NOT_ACTIVE for o in outcomes):
            # A redundant pair whose active changed since this command chose it: once more, on the active.
            from softplc.clients.session import open_live_session

            await asyncio.sleep(1.0)
            async with open_live_session(args.login) as again:
                outcomes, sent = await write_tags(again, assignments)
        for outcome in outcomes:
            print(outcome.message(), file=sys.stdout if outcome.accepted else sys.stderr)
        if not sent:
            print("softplc write: nothing written", file=sys.stderr)
        if any(o.rule is Rule.ACCESS_DENIED for o in outcomes):
            print("softplc write: this session may not write: log in as an operator or engineer with --user NAME", file=sys.stderr)
            return EXIT_NOT_ALLOWED
        return EXIT_OK if all(o.accepted for o in outcomes) else EXIT_REFUSED

    return _run("write", args, body)


def cmd_watch(args: argparse.Namespace) -> int:
    async def body(live: LiveSession) -> int:
        from softplc.clients.tags.watch import WatchEnded, watch

        follow = len(args.login.endpoints) > 1  # a redundant pair: follow its active
        opened: list[LiveSession] = []
        await live.read(await live.match(args.patterns))  # exact names come back unbrowsed: an unknown one is named here
        try:
            while True:
                tags = await live.match(args.patterns)
                try:
                    reason = await watch(live, tags, sys.stdout, endpoint=live.client.server_url.geturl(), interval_ms=args.interval,
                                         follow=follow)
                except WatchEnded as ended:
                    if not follow:
                        return _fail("watch", str(ended), EXIT_NO_CONNECTION)
                    print(f"softplc watch: {live.client.server_url.geturl()}: {str(ended).removeprefix('the server went away ')}; "
                          "following the active", file=sys.stderr)
                    live = await _the_active(args.login, FOLLOW_TIMEOUT)
                    opened.append(live)
                    continue
                print(f"softplc watch: {reason}", file=sys.stderr)
                return EXIT_OK
        finally:
            for session in opened:
                session.client.disconnect_socket()

    return _run("watch", args, body)


FOLLOW_TIMEOUT = 30.0  # s `watch` looks for a redundant pair's new active before it gives up


async def _the_active(login: Any, timeout: float) -> LiveSession:
    """A session on the pair's active (ServiceLevel ≥ 200), looked for until `timeout`; raises WatchEnded."""
    from softplc.clients.login import SERVICE_LEVEL_HEALTHY, connect, service_level
    from softplc.clients.session import LiveSession
    from softplc.clients.tags.watch import WatchEnded

    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        try:
            client = await connect(login)
            if await service_level(client) >= SERVICE_LEVEL_HEALTHY:
                return await LiveSession.open(client, login.namespace)
            client.disconnect_socket()
        except LoginError:
            pass
        if asyncio.get_running_loop().time() > deadline:
            raise WatchEnded(f"no active member of {login.endpoint} for {timeout:g} s")
        await asyncio.sleep(0.3)


def cmd_forces(args: argparse.Namespace) -> int:
    async def body(live: LiveSession) -> int:
        from softplc.clients.door_client import CommandError
        from softplc.clients.tags.forces import FORCES_HEADER, UNKNOWN_BY, list_forces
        from softplc.clients.tags.table import format_time, format_value, table_lines

        try:
            forced = await list_forces(live)
        except CommandError as error:
            return _fail("forces", str(error), EXIT_NOT_ALLOWED if error.not_allowed else EXIT_REFUSED)
        if args.format == "json":
            rows = [{"tag": f.tag, "value": f.value, "since": f.since.isoformat() if f.since else None,
                     "by": None if f.by == UNKNOWN_BY else f.by} for f in forced]
            print(json.dumps(rows, indent=2))
            return EXIT_OK
        if not forced:
            print("no forced tags")
            return EXIT_OK
        rows = [[f.tag, format_value(f.value, f.single), format_time(f.since), f.by] for f in forced]
        print("\n".join(table_lines(rows, FORCES_HEADER)))
        if any(f.by == UNKNOWN_BY for f in forced):
            print("(this server has no OPC UA door to the runtime's commands: who forced a tag is not known here)")
        return EXIT_OK

    return _run("forces", args, body)


def cmd_force(args: argparse.Namespace) -> int:
    from softplc.clients.tags.writing import parse_assignments

    try:
        assignments = parse_assignments(args.assignments)
    except ValueError as error:
        return _fail("force", str(error), EXIT_USAGE)
    calls = [("tags.force", {"tag": a.tag, "value": a.text}) for a in assignments]
    return _run("force", args, lambda live: _commands("force", live, calls))


def cmd_unforce(args: argparse.Namespace) -> int:
    calls = [("tags.unforce", {"tag": tag, "restore": args.restore}) for tag in args.tags]
    return _run("unforce", args, lambda live: _commands("unforce", live, calls))


async def _commands(command: str, live: LiveSession, calls: list[tuple[str, dict[str, Any]]]) -> int:
    """Call runtime commands one by one, printing what each did or why it was refused."""
    from softplc.clients.door_client import CommandError, call_command

    status = EXIT_OK
    for name, arguments in calls:
        try:
            print(await call_command(live.client, live.ns, name, arguments))
        except CommandError as error:
            print(f"softplc {command}: {error}", file=sys.stderr)
            if error.no_door:
                return EXIT_REFUSED
            status = max(status, EXIT_NOT_ALLOWED if error.not_allowed else EXIT_REFUSED)
            if error.not_allowed:
                print(f"softplc {command}: forcing needs the engineer role: log in with --user NAME as an engineer", file=sys.stderr)
                return status
    return status
