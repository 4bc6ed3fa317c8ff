"""`/metrics` on the HMI's port: who may scrape (servers.hmi.metrics), answered by the `metrics.scrape` query.

Prometheus scrapes without a browser session, so a scrape is let in by one of: a bearer token
(`Authorization: Bearer TOKEN`, the token file's text), a request from a loopback address while
`anonymous: loopback` (the default), or a logged-in HMI session; anything else is 401, and the
refusal logged per address and 10 s. The figures come from the metrics adapter through the
query, in one turn of the HMI's pacing (never into a scan cycle about to start).
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
import os
import secrets
from pathlib import Path
from typing import Any, Protocol

from aiohttp import web

from softplc.adapters.hmi.metrics_settings import MetricsSettings
from softplc.core.commands import CommandRefused
from softplc.core.origin import Origin
from softplc.core.plant import AdapterError, Plant
from softplc.core.roles import Role
from softplc.util.peers import PeerLog

log = logging.getLogger(__name__)

PATH = "/metrics"
QUERY = "metrics.scrape"


class _Server(Protocol):
    """What the route uses of the HMI server (softplc/adapters/hmi/server.py, which imports this module)."""

    url: str
    plant: Plant | None
    sessions: Any  # who is logged in (sessions.py)
    hub: Any  # its pacer keeps scrapes out of the scan's way (live.py)


class MetricsRoute:
    """The `/metrics` route of one HMI server."""

    def __init__(self, server: _Server, settings: MetricsSettings) -> None:
        self.server = server
        self.settings = settings
        self.token: str | None = None
        self._peer_log = PeerLog(log, service="metrics")

    def load_token(self, state_dir: Path) -> None:
        """Read (or make, on first start) the bearer token file; AdapterError when it is unusable."""
        path = self.settings.token_path(state_dir)
        if path is None:
            return
        try:
            self.token = read_or_make_token(path)
        except (OSError, ValueError) as error:
            raise AdapterError(f"metrics: token_file {path}: {error}") from None

    def routes(self) -> list[web.RouteDef]:
        return [web.get(PATH, self.scrape)] if self.settings.enabled else []

    @property
    def served(self) -> bool:
        """Whether /metrics answers: enabled, and the plant has the metrics query."""
        plant = self.server.plant
        return self.settings.enabled and plant is not None and QUERY in plant.commands

    def describe(self) -> str:
        who = ["a bearer token" if self.token else "", "loopback" if self.settings.anonymous_loopback else "", "HMI logins"]
        return f"metrics on {self.server.url.rstrip('/')}{PATH} (Prometheus text format; scrapes by {', '.join(w for w in who if w)})"

    async def scrape(self, request: web.Request) -> web.StreamResponse:
        refusal = self._refusal(request)
        if refusal is not None:
            self._peer_log.warning(request.remote or "?", "refused scrapes", "metrics: scrape from %s refused: %s", request.remote, refusal)
            raise web.HTTPUnauthorized(text=f"{refusal}\n", headers={"WWW-Authenticate": 'Bearer realm="softplc metrics"'})
        plant = self.server.plant
        if plant is None or QUERY not in plant.commands:
            raise web.HTTPServiceUnavailable(text="the runtime collects no metrics (started with --no-servers?)\n")
        async with self.server.hub.pacer.turn():  # collecting takes ~1 ms: not into a cycle about to start
            try:
                answer = await plant.commands.call(QUERY, {}, Origin("hmi", peer=request.remote or "", role=Role.VIEWER))
            except CommandRefused as refused:
                raise web.HTTPServiceUnavailable(text=f"{refused}\n") from None
        response = web.Response(text=answer["text"])
        response.headers["Content-Type"] = answer["content_type"]
        return response

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
        identity = self.server.sessions.identify(request)
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
