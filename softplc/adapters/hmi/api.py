"""The JSON API under /api/: what the pages use, and what scripts may use (docs/hmi.md).

    GET  /api/session            who am I, CSRF token, pages of the navigation, plant name
    POST /api/login              {"user", "password"} → session cookie + {"user", "role", "csrf"}
    POST /api/logout
    GET  /api/tags[?group=G&prefix=P&q=TEXT&names=A,B]   tags: declaration, value, quality, timestamp, writable
    GET  /api/tags/NAME
    POST /api/write              {"tag", "value"} or {"writes": [{"tag", "value"}, ...]} (X-CSRF-Token)
    GET  /api/tasks              runtime state, tasks, programs, and the _sys. tags behind each figure
    GET  /api/plant              the overview's model; /api/plant/map.png the factory map
    GET  /api/robots             the fleet and the robot-task compatibility with reasons
    GET  /api/views[/NAME[/svg]] user mimics
    GET  /api/diagnostics        the live channel's figures
    GET  /api/live               the WebSocket (live.py)

Writes go through `db.submit` with Origin("hmi", user, peer, role): the same validation, rules
and messages as OPC UA and Modbus. A write refused before it gets there (not logged in, no
CSRF token, a malformed item) is reported with `db.refused`, so every write reaches the write
listeners (the audit trail) whatever became of it.

One module of ~400 lines: one route table and its handlers, each a few lines over the plant API.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any, Protocol

from aiohttp import web

from softplc import __version__
from softplc.adapters.hmi.fanout import wire_value
from softplc.adapters.hmi.sessions import Identity
from softplc.adapters.hmi.untrusted import BadJson, loads, shown, shown_name
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, TagDatabase
from softplc.core.tags import Tag
from softplc.util.peers import peer_host
from softplc.util.suggest import did_you_mean

Pause = Callable[[], Awaitable[None]]

if TYPE_CHECKING:
    from softplc.adapters.hmi.live import Hub
    from softplc.adapters.hmi.plant import PlantModel
    from softplc.adapters.hmi.security import OriginPolicy
    from softplc.adapters.hmi.sessions import Sessions
    from softplc.adapters.hmi.settings import HmiSettings
    from softplc.adapters.hmi.shell import Shell
    from softplc.adapters.hmi.views import View
    from softplc.adapters.hmi.writelog import WriteLog
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Plant


class HmiServer(Protocol):
    """What the handlers use of the server (`softplc.adapters.hmi.server.HmiServer`, which builds them)."""

    config: PlantConfig
    settings: HmiSettings
    plant: Plant
    sessions: Sessions
    hub: Hub
    overview: PlantModel
    shell: Shell
    origins: OriginPolicy
    views: dict[str, View]
    writelog: WriteLog

log = logging.getLogger(__name__)

MAX_WRITES = 1000  # items in one write request
MAX_NAMES = 2000  # tags asked for by name in one request
MAX_HINTS = 3  # unknown names of one write request that get a "did you mean" (each searches every tag)
REPORT_SLICE = 100  # refused items reported between two looks at the scan (report_refused)
SOURCE = "hmi"


async def write_items(request: web.Request) -> list[Any]:
    """The items of a write request's body (`{"tag", "value"}` or `{"writes": [...]}`), or HTTPBadRequest."""
    try:
        body = loads(await request.read())
    except BadJson as error:
        raise web.HTTPBadRequest(text=f"the body is {error}") from None
    items = body.get("writes") if isinstance(body, dict) and "writes" in body else [body]
    if not isinstance(items, list) or not items or len(items) > MAX_WRITES:
        raise web.HTTPBadRequest(text=f"give {{\"tag\", \"value\"}} or {{\"writes\": [...]}} with 1 to {MAX_WRITES} items")
    return items


def outsider(peer: str) -> Origin:
    """The origin of a request from someone who has not logged in where visitors may not look: the least role."""
    return Origin(SOURCE, "", peer, Role.VIEWER)


async def report_refused(db: TagDatabase, origin: Origin, refusals: list[tuple[Any, Any, Rule, str]], pause: Pause) -> None:
    """Report refused items (name, value, rule, detail) to the write listeners (the audit trail), names and values clipped.

    ~10 µs each: a request of 1,000 lets a due scan cycle go first every REPORT_SLICE of them.
    """
    for start in range(0, len(refusals), REPORT_SLICE):
        if start:
            await pause()
        for name, value, rule, detail in refusals[start:start + REPORT_SLICE]:
            db.refused(origin, shown_name(name), shown(value), rule, detail)


def tag_json(tag: Tag, writable: bool) -> dict[str, Any]:
    definition = tag.definition
    return {
        "name": tag.name,
        "type": definition.type.value,
        "unit": definition.unit,
        "description": definition.description,
        "access": definition.access.value,
        "min": definition.min,
        "max": definition.max,
        "group": definition.group,
        "writable": writable,
        "value": wire_value(tag.value),
        "quality": tag.quality.value,
        "forced": tag.forced,
        "timestamp": round(tag.timestamp, 3),
    }


class Api:
    """The handlers of /api/ (except /api/live's protocol, in live.py)."""

    def __init__(self, server: HmiServer) -> None:
        self.server = server
        self._longest = (-1, 0)  # (tags in the database, the longest name's length)

    def routes(self) -> list[web.RouteDef]:
        return [
            web.get("/api/session", self.session),
            web.post("/api/login", self.login),
            web.post("/api/logout", self.logout),
            web.get("/api/tags", self.tags),
            web.get("/api/tags/{name}", self.tag),
            web.post("/api/write", self.write),
            web.get("/api/tasks", self.tasks),
            web.get("/api/plant", self.plant),
            web.get("/api/plant/map.png", self.map_image),
            web.get("/api/robots", self.robots),
            web.get("/api/views", self.views),
            web.get("/api/views/{name}", self.view),
            web.get("/api/views/{name}/svg", self.view_svg),
            web.get("/api/diagnostics", self.diagnostics),
            web.get("/api/live", self.live),
        ]

    # -- who is asking ------------------------------------------------------------------------

    def who(self, request: web.Request) -> Identity:
        identity = self.server.sessions.identify(request)
        if identity is None:
            raise web.HTTPUnauthorized(text="log in first (POST /api/login)")
        return identity

    # -- session ------------------------------------------------------------------------------

    async def session(self, request: web.Request) -> web.Response:
        server = self.server
        identity = server.sessions.identify(request)
        body: dict[str, Any] = {
            "plant": {"name": server.config.name, "description": server.config.description},
            "version": __version__,
            "instance": server.hub.instance,
            "simulated": server.plant.clock.simulated,
            "speed": getattr(server.plant.clock, "speed", None),
            "anonymous": server.settings.anonymous_role.value if server.settings.anonymous_role else None,
            "login_required": identity is None,
            "user": None,
            "role": None,
            "csrf": None,
            "pages": [],
            "banners": [],
        }
        if identity is not None:
            body.update(
                user=identity.user or None,
                role=identity.role.value,
                csrf=identity.session.csrf if identity.session else None,
                pages=server.shell.navigation(identity.role),
                banners=list(server.shell.banners),
            )
        return web.json_response(body)

    async def login(self, request: web.Request) -> web.Response:
        if request.content_type != "application/json":
            # An HTML form of another site can post form data but not JSON (that needs a CORS preflight).
            raise web.HTTPUnsupportedMediaType(text="send JSON: {\"user\": ..., \"password\": ...}")
        try:
            body = loads(await request.read())
        except BadJson as error:
            raise web.HTTPBadRequest(text=f"the body is {error}") from None
        user, password = (body.get("user"), body.get("password")) if isinstance(body, dict) else (None, None)
        if not isinstance(user, str) or not isinstance(password, str) or not user or len(user) > 64 or len(password) > 1024:
            raise web.HTTPBadRequest(text="give 'user' and 'password' as text")
        sessions = self.server.sessions
        session = await sessions.login(peer_host(request.remote), user, password)
        if session is None:
            raise web.HTTPUnauthorized(text="wrong user name or password (or too many failed attempts: wait a minute)")
        entry = sessions.users.get(user)
        response = web.json_response({"user": user, "role": entry.role.value if entry else None, "csrf": session.csrf})
        sessions.set_cookie(response, session)
        return response

    async def logout(self, request: web.Request) -> web.Response:
        sessions = self.server.sessions
        identity = sessions.identify(request)
        response = web.json_response({"ok": True})
        if identity is not None and identity.session is not None:
            if not sessions.csrf_ok(request, identity):
                raise web.HTTPForbidden(text="missing or wrong CSRF token (X-CSRF-Token)")
            sessions.logout(identity.session)
        sessions.clear_cookie(response)
        return response

    # -- tags -----------------------------------------------------------------------------------

    async def tags(self, request: web.Request) -> web.Response:
        identity = self.who(request)
        db = self.server.plant.tags
        query = request.query
        group, prefix = query.get("group"), query.get("prefix")
        text = query.get("q", "").casefold()
        names = query.get("names")
        if names is not None:
            candidates = [db[name] for name in dict.fromkeys(names.split(",")) if name in db][:MAX_NAMES]
        else:
            candidates = list(db)
        rows = []
        for tag in candidates:
            definition = tag.definition
            if group is not None and definition.group != group and not definition.group.startswith(group + "/"):
                continue
            if prefix is not None and not tag.name.startswith(prefix):
                continue
            if text and text not in tag.name.casefold():
                continue
            rows.append(tag_json(tag, db.writable(tag.name, identity.role)))
        response = web.json_response({"count": len(rows), "tags": rows})
        response.enable_compression()  # 10,000 tags are ~2 MB of JSON, ~10 times less compressed
        return response

    async def tag(self, request: web.Request) -> web.Response:
        identity = self.who(request)
        db = self.server.plant.tags
        name = request.match_info["name"]
        tag = db.get(name)
        if tag is None:
            raise web.HTTPNotFound(text=f"unknown tag '{name}'{did_you_mean(name, db.names())}")
        return web.json_response(tag_json(tag, db.writable(name, identity.role)))

    async def write(self, request: web.Request) -> web.Response:
        server = self.server
        db = server.plant.tags
        peer = peer_host(request.remote)
        items = await write_items(request)
        identity = server.sessions.identify(request)
        origin = Origin(SOURCE, identity.user, peer, identity.role) if identity is not None else outsider(peer)
        pairs = [(item.get("tag"), item.get("value")) if isinstance(item, dict) else (None, None) for item in items]
        # Whoever may not write at all is refused before any name is looked up: a viewer's request
        # of 1,000 unknown names must cost no more than a list of refusals.
        refusal = None
        if identity is None or identity.session is None:
            refusal = (403, Rule.ACCESS_DENIED, "log in to write")
        elif not server.sessions.csrf_ok(request, identity):
            refusal = (403, Rule.INVALID_REQUEST, "missing or wrong CSRF token (X-CSRF-Token)")
        elif not identity.role.may_write:
            refusal = (403, Rule.ACCESS_DENIED, f"role {identity.role.value} may not write")
        pause = server.hub.pacer.ready
        if refusal is not None:
            status, rule, detail = refusal
            await report_refused(db, origin, [(name, value, rule, detail) for name, value in pairs], pause)
            return web.json_response({"ok": False, "error": detail, "results": [
                {"tag": shown_name(name), "ok": False, "rule": rule.value, "detail": detail} for name, _ in pairs]}, status=status)
        results: list[dict[str, Any] | None] = [None] * len(pairs)
        valid: list[tuple[int, str, Any]] = []
        refusals: list[tuple[Any, Any, Rule, str]] = []
        longest = self._longest_name()
        for index, (name, value) in enumerate(pairs):
            if not isinstance(name, str) or not isinstance(value, (bool, int, float, str)):
                rule, detail = Rule.INVALID_REQUEST, "each write is {\"tag\": NAME, \"value\": a number, true/false or text}"
            elif len(name) > longest:  # no tag is that long: no lookup, no "did you mean"
                rule, detail = Rule.UNKNOWN_TAG, f"no such tag (no tag name is longer than {longest} characters)"
            else:
                valid.append((index, name, value))
                continue
            refusals.append((name, value, rule, detail))
            results[index] = {"tag": shown_name(name), "ok": False, "rule": rule.value, "detail": detail}
        await report_refused(db, origin, refusals, pause)
        old = {name: wire_value(db[name].value) for _, name, _ in valid if name in db}
        hints = MAX_HINTS  # "did you mean" searches every tag: a few per request
        for (index, name, value), rejected in zip(valid, db.submit([(name, value) for _, name, value in valid], origin)):
            if rejected is None:
                results[index] = {"tag": name, "ok": True, "old": old.get(name), "value": wire_value(db.validate(name, value, role=None))}
                continue
            detail = rejected.detail
            if rejected.rule is Rule.UNKNOWN_TAG and hints > 0:
                hints -= 1
                detail += did_you_mean(name, db.names())
            results[index] = {"tag": name, "ok": False, "rule": rejected.rule.value, "detail": detail}
        ok = all(result is not None and result["ok"] for result in results)
        return web.json_response({"ok": ok, "results": results}, status=200 if ok else 422)

    async def refuse_request(self, request: web.Request, reason: str) -> None:
        """Report each item of a write refused before its handler (the Origin check), as a missing CSRF token is."""
        try:
            items = await write_items(request)
        except web.HTTPException:
            return  # not a write at all: the server's log line is all there is to say
        identity = self.server.sessions.identify(request)
        peer = peer_host(request.remote)
        origin = Origin(SOURCE, identity.user, peer, identity.role) if identity is not None else outsider(peer)
        refusals = [(item.get("tag"), item.get("value")) if isinstance(item, dict) else (None, None) for item in items]
        await report_refused(self.server.plant.tags, origin, [(name, value, Rule.INVALID_REQUEST, reason) for name, value in refusals],
                             self.server.hub.pacer.ready)

    def _longest_name(self) -> int:
        db = self.server.plant.tags
        if self._longest[0] != len(db):
            self._longest = (len(db), max((len(name) for name in db.names()), default=0))
        return self._longest[1]

    # -- runtime, plant, robots, views ------------------------------------------------------------

    async def tasks(self, request: web.Request) -> web.Response:
        identity = self.who(request)
        plant = self.server.plant
        db = plant.tags
        tasks = []
        for task in plant.tasks:
            prefix = f"_sys.{task.name}."
            tasks.append({
                "name": task.name,
                "interval_ms": task.interval * 1e3,
                "priority": task.priority,
                "watchdog_ms": task.watchdog * 1e3,
                "prefix": prefix,
                "programs": [{"name": program.name, "program": program.reference,
                              "prefix": f"{prefix}{program.name}."} for program in task.programs],
            })
        return web.json_response({
            "state": "_sys.state",
            "error": "_sys.error",
            "time": "_sys.time",
            "reset_faults": {"tag": "_sys.reset_faults", "writable": db.writable("_sys.reset_faults", identity.role)},
            "reset_stats": {"tag": "_sys.reset_stats", "writable": db.writable("_sys.reset_stats", identity.role)},
            "tasks": tasks,
        })

    async def plant(self, request: web.Request) -> web.Response:
        self.who(request)
        return web.json_response(self.server.overview.describe())

    async def map_image(self, request: web.Request) -> web.Response:
        self.who(request)
        image = self.server.overview.map
        if image is None:
            raise web.HTTPNotFound(text="this plant has no map")
        return web.Response(body=image.png, content_type="image/png", headers={"Cache-Control": "private, max-age=3600"})

    async def robots(self, request: web.Request) -> web.Response:
        self.who(request)
        plant = self.server.overview
        return web.json_response({"robots": plant.robots, "tasks": plant.tasks, "compatibility": plant.compatibility})

    async def views(self, request: web.Request) -> web.Response:
        self.who(request)
        return web.json_response({"views": [{"name": view.name, "title": view.title} for view in self.server.views.values()]})

    async def view(self, request: web.Request) -> web.Response:
        self.who(request)
        return web.json_response(self._view(request).describe())

    async def view_svg(self, request: web.Request) -> web.Response:
        self.who(request)
        view = self._view(request)
        # Served for the page to parse, never to be opened as a document: no script may run even then.
        return web.FileResponse(view.svg, headers={"Content-Type": "image/svg+xml", "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'; sandbox"})

    def _view(self, request: web.Request) -> Any:
        name = request.match_info["name"]
        view = self.server.views.get(name)
        if view is None:
            raise web.HTTPNotFound(text=f"no view '{name}'{did_you_mean(name, self.server.views)}")
        return view

    async def diagnostics(self, request: web.Request) -> web.Response:
        self.who(request)
        try:
            since = float(request.query.get("since", 0.0))  # monotonic seconds: the delivery figures of frames sent since
        except ValueError:
            raise web.HTTPBadRequest(text="since is a number of seconds (time.monotonic())") from None
        return web.json_response({"live": self.server.hub.stats(since), "sessions": len(self.server.sessions)})

    async def live(self, request: web.Request) -> web.StreamResponse:
        identity = self.who(request)
        return await self.server.hub.handle(request, identity, self.server.origins, self.server.sessions)
