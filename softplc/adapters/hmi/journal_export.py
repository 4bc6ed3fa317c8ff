"""The alarm journal as a CSV download: `GET /api/alarms/journal.csv?alarm=&since=&until=&text=&user=&transition=`.

Read through the `alarms.journal` command with the session's origin, page by page (10,000 rows
per call, at most MAX_ROWS), and written by the journal's own `write_csv`: the same columns as
`softplc alarms journal --export csv` (a `time_utc` column in ISO 8601 beside the seconds).
`since` and `until` are epoch seconds or ISO 8601; `transition` a comma-separated list.
"""

from __future__ import annotations

import asyncio
import io
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from aiohttp import web

from softplc.core.commands import CommandRefused
from softplc.core.tagdb import Origin
from softplc.util.peers import peer_host

if TYPE_CHECKING:
    from softplc.adapters.hmi.api import HmiServer

PAGE = 10_000  # rows per alarms.journal call (its most)
MAX_ROWS = 200_000


class JournalExport:
    """Handler of /api/alarms/journal.csv."""

    def __init__(self, server: HmiServer) -> None:
        self.server = server

    def routes(self) -> list[web.RouteDef]:
        return [web.get("/api/alarms/journal.csv", self.export)]

    async def export(self, request: web.Request) -> web.Response:
        server = self.server
        identity = server.sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        if "alarms.journal" not in server.plant.commands:
            raise web.HTTPNotFound(text="this runtime keeps no alarm journal (no alarms: section)")
        query = request.query
        arguments: dict[str, Any] = {key: _time_or_text(query[key]) if key in ("since", "until") else query[key]
                                     for key in ("alarm", "since", "until", "text", "user") if query.get(key)}
        if query.get("transition"):
            arguments["transition"] = [item for item in query["transition"].split(",") if item]
        origin = Origin("hmi", identity.user, peer_host(request.remote), identity.role)
        rows: list[dict[str, Any]] = []
        try:
            while len(rows) < MAX_ROWS:
                page = await server.plant.commands.call("alarms.journal", {**arguments, "limit": PAGE, "offset": len(rows)}, origin)
                rows.extend(page)
                if len(page) < PAGE:
                    break
        except CommandRefused as refused:
            raise web.HTTPBadRequest(text=str(refused)) from None
        text = await asyncio.to_thread(_csv, rows)
        stamp = datetime.fromtimestamp(server.plant.clock.wall(), timezone.utc).strftime("%Y%m%d-%H%M%S")
        return web.Response(text=text, content_type="text/csv", charset="utf-8",
                            headers={"Content-Disposition": f'attachment; filename="alarm-journal-{stamp}.csv"'})


def _time_or_text(value: str) -> Any:
    try:
        return float(value)
    except ValueError:
        return value  # ISO 8601: the command reads it, or says what is wrong


def _csv(rows: list[dict[str, Any]]) -> str:
    from softplc.storage.alarm_journal import (  # the alarms' own format; loaded when asked for
        entries_from_dicts,
        write_csv,
    )

    stream = io.StringIO()
    write_csv(entries_from_dicts(rows), stream)
    return stream.getvalue()
