"""The HMI's door to the runtime's commands (`softplc/commands.py`): forcing, program control, online change...

    GET  /api/commands               the commands, each with `allowed` for the asking role
    POST /api/commands/{name}        body: the arguments (a JSON object, or nothing); X-CSRF-Token

The call goes through `runtime.commands.call` with the session's origin (`Origin("hmi", user,
peer, role)`), so the role is checked in the one place every path uses, and the call is reported
to the command listeners (the audit trail), carried out or refused. The answer is the command's
result as JSON (200), or `{"error": message}`: 403 when the role may not call it (or a session's
request lacks its CSRF token), 404 for an unknown command, 422 for any other refusal — an online
change's refusal adds `details` (differences, located problems; what `{"check": true}` returns).

A visitor without a session is the anonymous viewer (when the HMI lets visitors look): it may call
the commands that only read (`tags.forces`, `programs.list`), and nothing else, by the role check.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from aiohttp import web

from softplc.commands import CommandRefused, UnknownCommand
from softplc.peers import peer_host
from softplc.suggest import did_you_mean
from softplc.tagdb import Origin

if TYPE_CHECKING:
    from softplc.hmi.api import HmiServer

SOURCE = "hmi"


def command_routes(server: HmiServer) -> list[web.RouteDef]:
    """The routes of the commands door (the handlers read the server's sessions and runtime per request)."""
    door = CommandsDoor(server)
    return [web.get("/api/commands", door.listing), web.post("/api/commands/{name}", door.call)]


class CommandsDoor:
    """Handlers of /api/commands."""

    def __init__(self, server: HmiServer) -> None:
        self.server = server

    async def listing(self, request: web.Request) -> web.Response:
        identity = self.server.sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        commands = self.server.runtime.commands
        rows = []
        for name in commands.names():
            command = commands.get(name)
            assert command is not None
            rows.append({"name": name, "description": command.description, "arguments": dict(command.arguments),
                         "permission": command.permission.value, "allowed": command.permission.allows(identity.role)})
        return web.json_response({"role": identity.role.value, "commands": rows})

    async def call(self, request: web.Request) -> web.Response:
        server = self.server
        name = request.match_info["name"]
        identity = server.sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        if identity.session is not None and not server.sessions.csrf_ok(request, identity):
            return _error(403, "missing or wrong CSRF token (X-CSRF-Token)")
        arguments = await _arguments(request)
        commands = server.runtime.commands
        origin = Origin(SOURCE, identity.user, peer_host(request.remote), identity.role)
        command = commands.get(name)
        try:
            result = await commands.call(name, arguments, origin)
        except UnknownCommand as refused:
            return _error(404, f"{refused}{did_you_mean(name, commands.names())}")
        except CommandRefused as refused:
            # The registry refuses a role before anything else: the same question decides the status.
            status = 403 if command is not None and not command.permission.allows(identity.role) else 422
            body: dict[str, Any] = {"error": str(refused)}
            details = getattr(refused, "details", None)
            if isinstance(details, Mapping):
                body["details"] = dict(details)
            return _error(status, body)
        return web.Response(text=_dumps(result), content_type="application/json")


async def _arguments(request: web.Request) -> dict[str, Any]:
    """The body as the command's arguments: a JSON object, or nothing at all."""
    text = await request.text()
    if not text.strip():
        return {}
    try:
        body = json.loads(text)
    except ValueError:
        raise web.HTTPBadRequest(text="the body is not JSON: send the arguments as a JSON object") from None
    if not isinstance(body, dict):
        raise web.HTTPBadRequest(text="send the arguments as a JSON object, e.g. {\"tag\": \"t01_iFr\", \"value\": 0}")
    return body


def _error(status: int, body: str | dict[str, Any]) -> web.Response:
    payload = {"error": body} if isinstance(body, str) else body
    return web.Response(text=_dumps(payload), status=status, content_type="application/json")


def _dumps(value: Any) -> str:
    """JSON a browser can parse: non-finite floats as text, anything else unknown as its str()."""
    return json.dumps(_jsonable(value), ensure_ascii=False, default=str)


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if value != value else ("Infinity" if value > 0 else "-Infinity")
    if isinstance(value, Mapping):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(item) for item in value]
    return value
