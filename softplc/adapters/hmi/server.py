"""The HMI adapter: an aiohttp server in the runtime's own event loop (AppRunner + TCPSite).

It serves the front-end (`hmi/`, see assets.py), the JSON API (api.py) and the live WebSocket
(live.py). Like the OPC UA and Modbus servers it talks to the core only through the tag
database: snapshots to read, `db.on_change` to follow, `db.submit` to write.

    hmi = HmiServer(config, HmiSettings(port=0))
    runtime.add_adapter(hmi)
    await runtime.start()                # the HMI is handed the plant API (softplc/core/plant.py)
    hmi.url          "http://127.0.0.1:54321/"
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aiohttp import web

from softplc.adapters.hmi.alarm_feed import AlarmFeed
from softplc.adapters.hmi.api import Api
from softplc.adapters.hmi.assets import AssetsNotFound, find_assets
from softplc.adapters.hmi.browser import open_later
from softplc.adapters.hmi.command_door import CommandDoor
from softplc.adapters.hmi.expressions import ExpressionTable
from softplc.adapters.hmi.journal_export import JournalExport
from softplc.adapters.hmi.live import Hub
from softplc.adapters.hmi.metrics_route import MetricsRoute
from softplc.adapters.hmi.metrics_settings import MetricsSettings
from softplc.adapters.hmi.operations import install_operations
from softplc.adapters.hmi.pacing import pacer_for
from softplc.adapters.hmi.plant import PlantModel
from softplc.adapters.hmi.security import OriginPolicy, middleware
from softplc.adapters.hmi.sessions import Sessions
from softplc.adapters.hmi.settings import HmiSettings, settings_problems
from softplc.adapters.hmi.shell import Shell, builtin_pages
from softplc.adapters.hmi.supervisory import add_supervisory
from softplc.adapters.hmi.untrusted import clip
from softplc.adapters.hmi.views import View, load_views
from softplc.adapters.hmi.writelog import WriteLog
from softplc.config.yamlsource import ConfigError
from softplc.security.logins import PasswordLogins
from softplc.security.users import UserStore
from softplc.util.peers import PeerLog, peer_host
from softplc.util.plurals import plural

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

MAX_REQUEST_BYTES = 1024 * 1024


class HmiServer:
    """Adapter: the web HMI of one plant."""

    name = "hmi"

    def __init__(self, config: PlantConfig, settings: HmiSettings | None = None) -> None:
        views, view_problems = load_views(config)  # read and compiled once: the same check as hmi_problems
        problems = [*settings_problems(config), *view_problems]
        if problems:
            raise ConfigError(problems)
        self.config = config
        self.settings = settings or HmiSettings.from_config(config)
        self.views: dict[str, View] = {view.name: view for view in views}
        self.shell = Shell()
        install_operations(self)  # forcing, program control, online change, the audit page (operations.py)
        self.metrics_route = MetricsRoute(self, MetricsSettings.from_config(config))  # /metrics (servers.hmi.metrics)
        self.plant: Plant | None = None  # the plant API, once started
        self.url = ""
        self.port: int | None = None
        self.assets: Path | None = None
        self._runner: web.AppRunner | None = None
        self._unsubscribe_writes: Any = None

    # -- lifecycle ----------------------------------------------------------------------------

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        settings = self.settings
        self.plant = plant
        self.metrics_route.load_token(plant.state_dir)
        db = plant.tags
        try:
            self.assets = find_assets()
        except AssetsNotFound as error:
            raise AdapterError(str(error)) from None
        try:
            users = UserStore(settings.users_path(plant.state_dir))
        except ConfigError as error:
            raise AdapterError(f"HMI users file is invalid:\n{error}") from None
        self.sessions = Sessions(users, PasswordLogins(users, service="HMI"), anonymous_role=settings.anonymous_role,
                                 timeout=settings.session_timeout, secure=settings.tls)
        # Reading robots, tasks and drawing the map takes a moment: not on the loop.
        self.overview = await asyncio.to_thread(PlantModel, self.config, db)
        conditions = {key: condition for view in self.views.values() for key, condition in view.expressions.items()}
        self.expressions = ExpressionTable(db, conditions, plant.clock.wall)
        self.hub = Hub(db, self.expressions, plant.clock, rate=settings.max_update_rate, heartbeat=settings.heartbeat,
                       max_clients=settings.max_clients, max_clients_per_address=settings.max_clients_per_address,
                       pacer=pacer_for(plant))
        self.origins = OriginPolicy(settings.allowed_origins, extra_hosts=(settings.host.lower(),))
        self.shell.pages[:0] = builtin_pages(self.overview.has_fleet, [(view.name, view.title) for view in self.views.values()])
        add_supervisory(self.shell, plant.commands, self.assets)  # alarms, journal, trends: when the runtime has them
        if "alarms.summary" in plant.commands:
            self.hub.alarm_feed = AlarmFeed(plant.commands, plant.events, self.hub.pacer, plant.clock.wall,
                                            rate=settings.max_update_rate)
        self.writelog = WriteLog()
        self.shell.started = True
        app = self._application()
        ssl_context = await self._ssl_context(plant) if settings.tls else None
        runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=2.0)
        await runner.setup()
        site = web.TCPSite(runner, settings.host, settings.port, ssl_context=ssl_context, reuse_address=True)
        try:
            await site.start()
        except OSError as error:
            await runner.cleanup()
            reason = "port in use" if error.errno in (98, 48) else (error.strerror or str(error))
            raise AdapterError(f"HMI cannot listen on {settings.host}:{settings.port}: {reason}") from None
        self._runner = runner
        self.port = _bound_port(runner, settings.port)
        self.sessions.set_port(self.port)
        self.url = f"{settings.scheme}://{_url_host(settings.host)}:{self.port}/"
        self._unsubscribe_writes = db.on_write(self.writelog)
        self.hub.start()
        if self.hub.alarm_feed is not None:
            self.hub.alarm_feed.start()
        if settings.anonymous_role is not None and not settings.loopback:
            log.warning("HMI on %s lets anyone who reaches it look at the plant without logging in (servers.hmi.anonymous: viewer)", settings.host)
        if settings.open_browser:
            open_later(self.url)

    async def stop(self) -> None:
        if self._unsubscribe_writes is not None:
            self._unsubscribe_writes()
            self._unsubscribe_writes = None
        if self._runner is not None:
            if self.hub.alarm_feed is not None:
                await self.hub.alarm_feed.stop()
            await self.hub.stop()  # close every live client first: the runner waits for open handlers
            await self._runner.cleanup()
            self._runner = None
            self.sessions.close()

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py): live clients, sessions, drops, messages encoded."""
        if self._runner is None:
            return {}
        hub = self.hub
        return {"clients": len(hub.clients), "sessions": len(self.sessions), "clients_dropped": hub.dropped,
                "updates_encoded": hub.encoder.messages}

    def describe(self) -> str:
        settings = self.settings
        anonymous = "visitors may look without logging in" if settings.anonymous_role is not None else "log in to look"
        users = self.sessions.users if self._runner is not None else None
        count = len(users.entries()) if users is not None else 0
        where = users.path if users is not None else "users file"
        line = f"HMI on {self.url or settings.host} (open it in a browser; {anonymous}; {plural(count, 'user')} in {where})"
        return f"{line}\n{self.metrics_route.describe()}" if self._runner is not None and self.metrics_route.served else line

    # -- parts of start -------------------------------------------------------------------------

    def _application(self) -> web.Application:
        assert self.assets is not None
        api, door = Api(self), CommandDoor(self)
        peer_log = PeerLog(log, service="HMI")

        async def refused(request: web.Request, reason: str) -> None:
            # As for a missing CSRF token: logged (rate-limited per address) and, for a write or a
            # command, reported to the audit trail with what it asked for.
            peer = peer_host(request.remote)
            peer_log.warning(peer, "cross-origin requests refused", "HMI: %s %s from %s refused: %s", request.method,
                             clip(request.path, 100), peer, reason, detail=reason)
            if request.path == "/api/write":
                await api.refuse_request(request, reason)
            elif request.path.startswith("/api/commands/"):
                await door.refuse_request(request, reason)

        app = web.Application(middlewares=[middleware(self.origins, refused)], client_max_size=MAX_REQUEST_BYTES)
        index = self.assets / "index.html"

        async def page(request: web.Request) -> web.FileResponse:
            return web.FileResponse(index)

        app.add_routes([web.get("/", page), web.get("/index.html", page)])
        app.add_routes(api.routes())
        app.add_routes(door.routes())
        app.add_routes(JournalExport(self).routes())
        app.add_routes(self.shell.routes)
        app.add_routes(self.metrics_route.routes())
        app.router.add_static("/static/", self.assets, follow_symlinks=False)
        modules = self.assets / "node_modules"
        if modules.is_dir():  # third-party front-end libraries, installed by `npm ci` (hmi/package.json)
            app.router.add_static("/vendor/", modules, follow_symlinks=False)
        return app

    async def _ssl_context(self, plant: Plant) -> Any:
        from softplc.adapters.hmi.tls import ensure_certificate, server_context
        from softplc.core.plant import AdapterError

        settings = self.settings
        try:
            if settings.certificate is not None and settings.private_key is not None:
                certificate, key = settings.certificate, settings.private_key
            else:
                certificate, key = await asyncio.to_thread(ensure_certificate, settings.tls_dir(plant.state_dir), [settings.host])
            return server_context(certificate, key)
        except (OSError, ValueError) as error:
            raise AdapterError(f"HMI TLS certificate: {error}") from None


def _bound_port(runner: web.AppRunner, asked: int) -> int:
    for address in runner.addresses:
        if isinstance(address, tuple) and len(address) >= 2:
            return int(address[1])
    return asked


def _url_host(host: str) -> str:
    if host in ("0.0.0.0", "::", ""):
        import socket

        return socket.gethostname()
    return f"[{host}]" if ":" in host else host
