"""`softplc redundancy keys DIR` (the pair's sync-link certificates) and `softplc redundancy status` (over OPC UA)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


def add_commands(subparsers: Any) -> None:
    redundancy = subparsers.add_parser("redundancy", help="a redundant pair of runtimes: certificates, status",
                                       description="Tools for a hot-standby pair of runtimes (docs/redundancy.md).")
    commands = redundancy.add_subparsers(dest="redundancy_command", required=True, metavar="COMMAND")
    keys = commands.add_parser("keys", help="make the sync link's certificate and key of each member",
                               description="Write NAME.crt and NAME.key for each member into DIR (EC P-256, self-signed, "
                               "10 years). Copy both certificates and its own key to each machine; the peer pins each certificate.")
    keys.add_argument("directory", metavar="DIR", type=Path)
    keys.add_argument("--members", default="a,b", help="the two members' names, comma separated (default a,b)")
    keys.add_argument("--force", action="store_true", help="replace certificates that exist")
    keys.set_defaults(func=cmd_keys)

    status = commands.add_parser("status", help="the pair as a running runtime sees it (OPC UA)",
                                 description="Ask a running runtime for its redundancy status: its role, the epoch, the active, "
                                 "the peer, the sync age and the coordinator.")
    status.add_argument("--format", choices=("table", "json"), default="table")
    from softplc.clients.login import add_login_arguments

    add_login_arguments(status)
    status.set_defaults(func=cmd_status)


def cmd_keys(args: argparse.Namespace) -> int:
    from softplc.security.pair_certificates import fingerprint, make_pair

    names = [name.strip() for name in args.members.split(",") if name.strip()]
    if len(names) != 2 or names[0] == names[1]:
        print("softplc redundancy keys: --members takes two different names, e.g. a,b", file=sys.stderr)
        return 2
    existing = [args.directory / f"{name}.crt" for name in names if (args.directory / f"{name}.crt").exists()]
    if existing and not args.force:
        print(f"softplc redundancy keys: {existing[0]} exists (--force replaces it; the peer must then get the new one)", file=sys.stderr)
        return 1
    for name in names:
        certificate, key = make_pair(args.directory, name)
        print(f"{name}: {certificate} (sha256 {fingerprint(certificate)[:16]}...), key {key}")
    return 0


def cmd_status(args: argparse.Namespace) -> int:
    import asyncio

    from softplc.clients.door_client import CommandError, call_command
    from softplc.clients.login import LoginError, login_from_args
    from softplc.clients.session import open_live_session

    try:
        login = login_from_args(args)
    except LoginError as error:
        print(f"softplc redundancy status: {error}", file=sys.stderr)
        return error.exit_status

    async def ask() -> Any:
        async with open_live_session(login) as live:
            return await call_command(live.client, live.ns, "redundancy.status", {})

    try:
        status = asyncio.run(ask())
    except LoginError as error:
        print(f"softplc redundancy status: {error}", file=sys.stderr)
        return error.exit_status
    except CommandError as error:
        print(f"softplc redundancy status: {error}", file=sys.stderr)
        return 1
    except (OSError, asyncio.TimeoutError) as error:
        print(f"softplc redundancy status: lost the connection to {login.endpoint}: {error}", file=sys.stderr)
        return 3
    if not isinstance(status, dict):
        status = json.loads(status) if isinstance(status, str) and status.startswith("{") else {"status": status}
    if args.format == "json":
        print(json.dumps(status, indent=2))
        return 0
    for key in ("member", "role", "epoch", "active", "service_level", "peer", "peer_state", "sync_age_s", "failovers", "refused",
                "coordinator_ok"):
        print(f"{key:15} {status.get(key)}")
    return 0
