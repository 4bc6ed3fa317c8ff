"""`softplc apply [CONFIG]`: an online change of a running plant, from this machine or another.

It logs in over OPC UA as an engineer and calls the runtime's `programs.apply` command through the
server's door to the commands (`Objects/Commands`, `Call(name, argumentsJSON) -> resultJSON`,
softplc/opcua/commands.py). The runtime re-reads the file it was started with and checks it
(softplc/online_change.py); this command prints what it answers. CONFIG only says where the
plant serves (its `servers.opcua` endpoint and namespace), unless --endpoint is given.

    softplc apply --user erin                     # password from a prompt, $SOFTPLC_PASSWORD or --password-stdin
    softplc apply --check --user erin             # show the differences, apply nothing
    softplc apply --endpoint opc.tcp://plc7:4840/softplc/ --user erin --security SignAndEncrypt,cert.der,key.pem

Exit statuses: 0 applied (or checked, or nothing to apply); 1 no connection or login, or refused
for another reason; 2 the file or a program has problems (`FILE:LINE:COL: message` each); 3 the
change needs a restart of the runtime (the reasons and the differences are printed); 4 the
user's role may not apply online changes (an engineer's may).
"""

from __future__ import annotations

import argparse
import asyncio
import getpass
import json
import os
import sys
from typing import Any

EXIT_OK, EXIT_FAILURE, EXIT_PROBLEMS, EXIT_RESTART, EXIT_NOT_ALLOWED = 0, 1, 2, 3, 4
PASSWORD_ENV = "SOFTPLC_PASSWORD"
COMMANDS_OBJECT = "Commands"


class ApplyError(Exception):
    """Why the command could not be called, and the exit status that says so."""

    def __init__(self, message: str, status: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.status = status


def add_commands(subparsers: Any) -> None:
    """Register `apply` with the softplc command line."""
    parser = subparsers.add_parser(
        "apply",
        help="apply an online change to a running plant (engineer)",
        description="Ask a running softplc to re-read its configuration and apply the changes of its programs "
        "(code, params, bind, on_fault, restart, enabled) at a scan boundary, without stopping the plant. "
        "Nothing is applied if anything is wrong; changes that need a restart are refused with the reason.",
        epilog="Example: softplc apply --user erin | softplc apply --check --user erin",
    )
    parser.add_argument("config", nargs="?", default="tagdb.yaml", help="the plant's configuration: where it serves (default tagdb.yaml)")
    parser.add_argument("--check", action="store_true", help="check and show the differences, apply nothing")
    parser.add_argument("--endpoint", help="the runtime's OPC UA endpoint (default: from CONFIG's servers.opcua)")
    parser.add_argument("--user", help=f"an engineer's user name (password: --password-stdin, ${PASSWORD_ENV} or a prompt)")
    parser.add_argument("--password-stdin", action="store_true", help="read the password from the first line of stdin")
    parser.add_argument("--security", metavar="MODE[,CERT,KEY]",
                        help="None, Sign or SignAndEncrypt (Basic256Sha256) with a client certificate")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds to wait for the runtime's answer (default 60)")
    parser.set_defaults(func=cmd_apply)


def cmd_apply(args: argparse.Namespace) -> int:
    try:
        endpoint, namespace = _where(args)
        password = _password(args)
        reply = asyncio.run(call(endpoint, namespace, "programs.apply", {"check": True} if args.check else {},
                                 user=args.user, password=password, security=args.security, timeout=args.timeout))
    except ApplyError as error:
        print(f"softplc apply: {error}", file=sys.stderr)
        return error.status
    if not reply.get("ok"):
        message = str(reply.get("error", "refused"))
        print(message, file=sys.stderr)
        if " problem(s):" in message.split("\n", 1)[0]:
            return EXIT_PROBLEMS
        if "need a restart" in message.split("\n", 1)[0]:
            return EXIT_RESTART
        return EXIT_FAILURE
    print(report(reply.get("result") or {}))
    return EXIT_OK


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


async def call(endpoint: str, namespace: str, name: str, arguments: dict[str, Any], *, user: str | None, password: str | None,
               security: str | None, timeout: float) -> dict[str, Any]:
    """Call a runtime command through Objects/Commands; the decoded resultJSON ({"ok": ..., ...})."""
    from asyncua import Client, ua

    client = Client(endpoint, timeout=timeout)
    client.session_timeout = 60_000  # what softplc grants at most (asyncua asks for an hour and warns when refused)
    if user:
        client.set_user(user)
        client.set_password(password or "")
    if security:
        await _secure(client, security)
    try:
        await client.connect()
    except Exception as error:
        raise ApplyError(f"cannot connect to {endpoint}: {error!r}") from None
    try:
        names = await client.get_namespace_array()
        if namespace not in names:
            raise ApplyError(f"{endpoint} has no namespace {namespace!r}: is it a softplc?")
        ns = names.index(namespace)
        door = client.get_node(ua.NodeId(COMMANDS_OBJECT, ns))
        try:
            answer = await door.call_method(ua.NodeId(f"{COMMANDS_OBJECT}.Call", ns), name, json.dumps(arguments))
        except ua.UaStatusCodeError as error:
            code = ua.StatusCode(error.code).name
            if code == "BadUserAccessDenied":
                who = f"user {user}" if user else "an anonymous session"
                raise ApplyError(f"{who} may not apply online changes: log in as an engineer (--user)", EXIT_NOT_ALLOWED) from None
            if code in ("BadNodeIdUnknown", "BadMethodInvalid", "BadNotImplemented"):
                raise ApplyError(f"{endpoint} has no door to the runtime's commands (Objects/Commands): an older softplc?") from None
            raise ApplyError(f"{name} refused by the server: {code}") from None
        return json.loads(answer)
    finally:
        await client.disconnect()


async def _secure(client: Any, text: str) -> None:
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    from softplc.latency.certificate import MODES, Security, application_uri

    try:
        security = Security.parse(text)
    except ValueError as error:
        raise ApplyError(str(error)) from None
    if not security.secured:
        return
    if security.certificate is None or security.key is None:
        raise ApplyError("--security Sign/SignAndEncrypt needs the client certificate and key: MODE,CERT,KEY")
    client.application_uri = application_uri(security.certificate)
    await client.set_security(SecurityPolicyBasic256Sha256, str(security.certificate), str(security.key), mode=MODES[security.mode])


def _where(args: argparse.Namespace) -> tuple[str, str]:
    """The endpoint and namespace: --endpoint, else CONFIG's servers.opcua (without checking the whole file)."""
    from pathlib import Path

    from softplc.opcua.settings import DEFAULT_NAMESPACE, OpcUaSettings
    from softplc.yamlsource import ConfigError, load_yaml

    section: dict[str, Any] = {}
    path = Path(args.config)
    if path.exists():
        try:
            data, _ = load_yaml(path)
        except ConfigError as error:
            raise ApplyError(f"cannot read {path}: {error}", EXIT_PROBLEMS) from None
        servers = data.get("servers") if isinstance(data, dict) else None
        opcua = servers.get("opcua") if isinstance(servers, dict) else None
        section = opcua if isinstance(opcua, dict) else {}
    elif args.endpoint is None:
        raise ApplyError(f"no {path}: give the plant's configuration, or --endpoint URL")
    settings = OpcUaSettings.from_section(section, path.parent)
    return args.endpoint or settings.endpoint, str(section.get("namespace", DEFAULT_NAMESPACE))


def _password(args: argparse.Namespace) -> str | None:
    if not args.user:
        return None
    if args.password_stdin:
        return sys.stdin.readline().rstrip("\n")
    if os.environ.get(PASSWORD_ENV):
        return os.environ[PASSWORD_ENV]
    if sys.stdin.isatty():
        return getpass.getpass(f"password of {args.user}: ")
    raise ApplyError(f"no password for {args.user}: use --password-stdin or ${PASSWORD_ENV}")
