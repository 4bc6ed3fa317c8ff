"""The audit page's CSV export: `GET /api/audit.csv?since=...&tag=...` → the matching entries as a file.

It asks the audit trail through its command (`audit.query`, engineers only) with the session's
origin, exactly as the page does, and writes the rows with the audit package's own CSV writer, so
the file has the columns of `softplc audit --format csv`. Every filter of the page is a query
parameter named like the command's argument; `limit` defaults to the most one query returns.
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING, Any

from aiohttp import web

from softplc.core.commands import CommandRefused
from softplc.core.tagdb import Origin
from softplc.util.peers import peer_host

if TYPE_CHECKING:
    from softplc.adapters.hmi.api import HmiServer

TEXT_FILTERS = ("since", "until", "tag", "command", "user", "source", "peer", "kind", "result")


def audit_routes(server: HmiServer) -> list[web.RouteDef]:
    async def export(request: web.Request) -> web.Response:
        identity = server.sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        commands = server.plant.commands
        if "audit.query" not in commands:
            raise web.HTTPNotFound(text="this runtime keeps no audit trail (audit: enabled: false, or --no-audit)")
        arguments: dict[str, Any] = {key: request.query[key] for key in TEXT_FILTERS if request.query.get(key)}
        for key in ("since", "until"):  # epoch seconds from the page; ISO 8601 text from a person
            try:
                arguments[key] = float(arguments[key])
            except (KeyError, ValueError):
                pass
        for key in ("limit", "offset"):
            if request.query.get(key):
                try:
                    arguments[key] = int(request.query[key])
                except ValueError:
                    raise web.HTTPBadRequest(text=f"'{key}' must be a whole number") from None
        arguments.setdefault("limit", 10_000)
        origin = Origin("hmi", identity.user, peer_host(request.remote), identity.role)
        try:
            rows = await commands.call("audit.query", arguments, origin)
        except CommandRefused as refused:
            status = 403 if not identity.role.may_engineer else 422
            raise _refusal(status, str(refused)) from None
        from softplc.storage.audit.entry import AuditEntry
        from softplc.storage.audit.queries import write_csv

        stream = io.StringIO()
        write_csv((AuditEntry.from_dict(row) for row in rows), stream)
        stamp = server.plant.clock.wall()
        return web.Response(text=stream.getvalue(), content_type="text/csv", charset="utf-8", headers={
            "Content-Disposition": f'attachment; filename="audit-{int(stamp)}.csv"'})

    return [web.get("/api/audit.csv", export)]


def _refusal(status: int, message: str) -> web.HTTPException:
    return web.HTTPForbidden(text=message) if status == 403 else web.HTTPUnprocessableEntity(text=message)
