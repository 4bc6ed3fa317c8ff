"""The HMI's door to the runtime's commands (`softplc/core/commands.py`): what pages and scripts do besides writing tags.

    GET  /api/commands           the commands, each with its arguments and whether the session's role may call it
    POST /api/commands/NAME      JSON object of arguments → {"ok": true, "command", "result", "time"}
                                 or {"ok": false, "command", "error"[, "details"]}: 403 refused for the
                                 role (or no login / CSRF token), 404 no such command, 400 a body that
                                 is not a JSON object, 422 any other refusal, in the runtime's words (an
                                 online change's refusal adds `details`: differences, located problems)

Every call goes through `plant.commands.call` with `Origin("hmi", user, peer, role)`: the
registry checks the role and reports the call (the audit trail), exactly as for OPC UA and the
CLI. Commands that only read (`Permission.VIEW`: alarm lists, history) are open to whoever may
look at the HMI, the anonymous viewer included; every other command needs a login and the
session's CSRF token in `X-CSRF-Token`, like a write.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from aiohttp import web

from softplc.adapters.hmi.untrusted import BadJson, loads, shown_name
from softplc.adapters.hmi.wire import json_response
from softplc.core.commands import CommandRefused, Permission, UnknownCommand
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.util.peers import PeerLog, peer_host
from softplc.util.suggest import did_you_mean

if TYPE_CHECKING:
    from softplc.adapters.hmi.api import HmiServer

log = logging.getLogger(__name__)

SOURCE = "hmi"


class CommandDoor:
    """Handlers of /api/commands."""

    def __init__(self, server: HmiServer) -> None:
        self.server = server
        self.peer_log = PeerLog(log, service="HMI")

    def routes(self) -> list[web.RouteDef]:
        return [web.get("/api/commands", self.listing), web.post("/api/commands/{name}", self.call)]

    async def listing(self, request: web.Request) -> web.Response:
        identity = self.server.sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        commands = self.server.plant.commands
        rows = []
        for name in commands.names():
            command = commands.get(name)
            assert command is not None
            rows.append({"name": name, "description": command.description, "arguments": dict(command.arguments),
                         "permission": command.permission.value, "allowed": command.permission.allows(identity.role)})
        return json_response({"role": identity.role.value, "commands": rows})

    async def call(self, request: web.Request) -> web.Response:
        server = self.server
        name = request.match_info["name"]
        sessions = server.sessions
        identity = sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        arguments, problem = await _arguments(request)
        if problem:
            return json_response({"ok": False, "command": name, "error": problem}, status=400)
        commands = server.plant.commands
        command = commands.get(name)
        peer = peer_host(request.remote)
        if command is not None and command.permission is not Permission.VIEW:
            # A state-changing command: as for a write, a login and the session's CSRF token.
            why = ("log in to " + (command.description or name) if identity.session is None
                   else None if sessions.csrf_ok(request, identity) else "missing or wrong CSRF token (X-CSRF-Token)")
            if why is not None:  # reported like a refused write (the audit trail), never reaching the command
                commands.refused(name, arguments, Origin(SOURCE, identity.user, peer, identity.role), why)
                self.peer_log.warning(peer, "refused commands", "HMI: command %s from %s refused: %s", shown_name(name), peer, why)
                return json_response({"ok": False, "command": name, "error": why}, status=403)
        origin = Origin(SOURCE, identity.user, peer, identity.role)
        try:
            result = await commands.call(name, arguments, origin)
        except UnknownCommand as refused:
            error = f"{refused}{did_you_mean(name, commands.names())}"
            return json_response({"ok": False, "command": name, "error": error}, status=404)
        except CommandRefused as refused:
            # The registry refuses a role before anything else: the same question decides the status.
            by_role = command is not None and not command.permission.allows(identity.role)
            self._note(origin, name, command, False, str(refused))
            answer: dict[str, Any] = {"ok": False, "command": name, "error": str(refused)}
            details = getattr(refused, "details", None)
            if isinstance(details, Mapping):
                answer["details"] = dict(details)
            return json_response(answer, status=403 if by_role else 422)
        except Exception as error:  # a broken handler: the caller gets JSON, the log the traceback
            log.exception("HMI: command %s failed", name)
            return json_response({"ok": False, "command": name, "error": f"{name} failed: {error}"}, status=500)
        self._note(origin, name, command, True, result if isinstance(result, str) else "")
        return json_response({"ok": True, "command": name, "result": result, "time": round(server.plant.clock.wall(), 3)})

    async def refuse_request(self, request: web.Request, reason: str) -> None:
        """Report a call refused before its handler (the Origin check) to the audit trail, as a missing CSRF token is."""
        name = request.match_info.get("name")
        if request.method != "POST" or not name:
            return
        identity = self.server.sessions.identify(request)
        peer = peer_host(request.remote)
        arguments, _ = await _arguments(request)
        origin = Origin(SOURCE, identity.user, peer, identity.role) if identity is not None else Origin(SOURCE, "", peer, Role.VIEWER)
        self.server.plant.commands.refused(name, arguments, origin, reason)

    def _note(self, origin: Origin, name: str, command: Any, accepted: bool, detail: str) -> None:
        if command is not None and command.permission is not Permission.VIEW:
            self.server.writelog.command(origin, name, accepted, detail)


_JSON_TYPES = {list: "an array", str: "text", int: "a number", float: "a number", bool: "true/false", type(None): "null"}


async def _arguments(request: web.Request) -> tuple[dict[str, Any], str]:
    """The request's arguments, or a problem saying what is wrong with the body."""
    body = await request.read()
    if not body.strip():
        return {}, ""
    try:
        arguments = loads(body)
    except BadJson as error:
        return {}, f"the body is {error}: send the arguments as a JSON object, e.g. {{\"alarm\": \"t01_input_full\"}}"
    if not isinstance(arguments, dict):
        return {}, f"the arguments are a JSON object ({{\"name\": value, ...}}), not {_JSON_TYPES.get(type(arguments), 'that')}"
    return arguments, ""
