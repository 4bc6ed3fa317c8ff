"""The `/metrics` adapter: Prometheus's text format on the HMI's web server, for those allowed to scrape.

    hmi = HmiServer(config, settings)
    runtime.add_adapter(MetricsAdapter(hmi, MetricsSettings.from_config(config)))   # before the HMI
    runtime.add_adapter(hmi)

The route is added through the HMI's shell (softplc/adapters/hmi/shell.py) when the adapter is made, so
it must be made before the runtime starts; it listens to the core (writes, command calls) from
the runtime's start. A scrape is answered by prometheus_client's aiohttp handler over a registry
of its own (this plant's collector, plus the process's CPU, memory and garbage collector), and
takes one turn of the HMI's pacing (softplc/adapters/hmi/pacing.py): never into a scan cycle about to start.

Who may scrape is `servers.hmi.metrics` (settings.py): a bearer token, a loopback address, or a
logged-in HMI session; anything else is refused (401) and the refusal logged per address and 10 s.
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
import os
import secrets
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aiohttp import web

from softplc.adapters.metrics.counters import CommandCounts, WriteCounts
from softplc.adapters.metrics.settings import MetricsSettings
from softplc.util.peers import PeerLog

if TYPE_CHECKING:
    from softplc.adapters.hmi.server import HmiServer
    from softplc.app.runtime import Runtime

log = logging.getLogger(__name__)

PATH = "/metrics"


class MetricsAdapter:
    """Adapter: `/metrics` on the HMI's port (see the module docstring)."""

    name = "metrics"

    def __init__(self, hmi: HmiServer, settings: MetricsSettings | None = None) -> None:
        self.hmi = hmi
        self.settings = settings or MetricsSettings()
        self.token: str | None = None
        self.scrapes = 0
        self._handler: Any = None
        self._undo: list[Any] = []
        self._peer_log = PeerLog(log, service="metrics")
        hmi.shell.add_routes([web.get(PATH, self.scrape)])

    async def start(self, runtime: Runtime) -> None:
        from prometheus_client import CollectorRegistry, GCCollector, PlatformCollector, ProcessCollector
        from prometheus_client.aiohttp import make_aiohttp_handler

        from softplc.adapters.metrics.collector import RuntimeCollector
        from softplc.app.runtime import AdapterError

        path = self.settings.token_path(runtime.state_dir)
        if path is not None:
            try:
                self.token = read_or_make_token(path)
            except (OSError, ValueError) as error:
                raise AdapterError(f"metrics: token_file {path}: {error}") from None
        writes, calls = WriteCounts(), CommandCounts(runtime.commands)
        self._undo = [runtime.db.on_write(writes), runtime.commands.on_call(calls)]
        registry = CollectorRegistry()
        registry.register(RuntimeCollector(runtime, writes, calls))
        ProcessCollector(registry=registry)
        PlatformCollector(registry=registry)
        GCCollector(registry=registry)
        self.registry = registry
        self._handler = make_aiohttp_handler(registry)

    async def stop(self) -> None:
        for undo in self._undo:
            undo()
        self._undo = []
        self._handler = None

    def describe(self) -> str:
        who = ["a bearer token" if self.token else "", "loopback" if self.settings.anonymous_loopback else "", "HMI logins"]
        return f"metrics on {self.hmi.url.rstrip('/') or 'the HMI'}{PATH} (Prometheus text format; scrapes by {', '.join(w for w in who if w)})"

    # -- the route --------------------------------------------------------------------------

    async def scrape(self, request: web.Request) -> web.StreamResponse:
        if not self.settings.enabled:
            raise web.HTTPNotFound(text="metrics are off (servers.hmi.metrics.enabled: false)")
        refusal = self._refusal(request)
        if refusal is not None:
            self._peer_log.warning(request.remote or "?", "refused scrapes", "metrics: scrape from %s refused: %s", request.remote, refusal)
            raise web.HTTPUnauthorized(text=f"{refusal}\n", headers={"WWW-Authenticate": 'Bearer realm="softplc metrics"'})
        if self._handler is None:
            raise web.HTTPServiceUnavailable(text="the runtime is not running\n")
        self.scrapes += 1
        async with self.hmi.hub.pacer.turn():  # collecting takes ~1 ms: not into a cycle about to start
            return await self._handler(request)

    def _refusal(self, request: web.Request) -> str | None:
        """Why this request may not scrape, or None when it may."""
        header = request.headers.get("Authorization", "")
        if header:
            scheme, _, sent = header.partition(" ")
            if self.token is not None and scheme.lower() == "bearer" and hmac.compare_digest(sent.strip().encode(), self.token.encode()):
                return None
            return "wrong bearer token" if self.token is not None else "no token is configured (servers.hmi.metrics.token_file)"
        if self.settings.anonymous_loopback and _loopback(request.remote):
            return None
        identity = self.hmi.sessions.identify(request)
        if identity is not None and identity.session is not None:
            return None
        local = ", or scrape from this computer" if self.settings.anonymous_loopback else ""
        return f"send Authorization: Bearer TOKEN (servers.hmi.metrics.token_file){local}, or log in to the HMI"


def _loopback(address: str | None) -> bool:
    try:
        return address is not None and ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


def read_or_make_token(path: Path) -> str:
    """The token in `path` (the whole file, surrounding whitespace trimmed); a new random one written there (mode 600) when the file is missing."""
    if path.exists():
        token = path.read_text(encoding="utf-8").strip()
        if len(token) < 16:
            raise ValueError("the token is shorter than 16 characters")
        return token
    path.parent.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(32)
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "w", encoding="utf-8") as stream:
        stream.write(token + "\n")
    log.info("metrics: made a bearer token for scrapes in %s", path)
    return token
