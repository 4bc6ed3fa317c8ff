"""HTTP safety of the HMI: response headers, the Host check and the Origin check.

- Every response carries a strict Content-Security-Policy (scripts, styles, images and
  connections from this origin only; no inline script or style; no framing), nosniff, no
  referrer, and `Cache-Control: no-store` under /api/.
- **Host check** (DNS rebinding): a page of evil.example whose name is made to resolve to
  127.0.0.1 would otherwise be "same origin" with us. Only requests naming us by an IP address,
  localhost, this computer's name or a host of `allowed_origins` are served.
- **Origin check**: state-changing requests and the live WebSocket must come from our own
  origin (or one in `allowed_origins`); a browser always says where a request comes from.
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Awaitable, Callable
from urllib.parse import urlsplit

from aiohttp import web

from softplc.adapters.hmi.untrusted import clip

CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; connect-src 'self'; "
    "font-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'"
)
HEADERS = {
    "Content-Security-Policy": CONTENT_SECURITY_POLICY,
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "X-Frame-Options": "DENY",
    "Cross-Origin-Opener-Policy": "same-origin",
    "Cross-Origin-Resource-Policy": "same-origin",
}
UNSAFE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})


class OriginPolicy:
    """Which Host names and Origins the HMI answers."""

    def __init__(self, allowed_origins: tuple[str, ...] = (), extra_hosts: tuple[str, ...] = ()) -> None:
        self.allowed_origins = frozenset(origin.lower().rstrip("/") for origin in allowed_origins)
        names = {"localhost", socket.gethostname().lower(), socket.getfqdn().lower(), *extra_hosts}
        names.update((urlsplit(origin).hostname or "") for origin in self.allowed_origins)
        self.host_names = frozenset(name for name in names if name)

    def host_ok(self, request: web.Request) -> bool:
        """Whether the request names us (not a rebound domain name)."""
        host = urlsplit(f"//{request.host}").hostname or ""
        if host in self.host_names or host.endswith(".localhost"):
            return True
        try:
            ipaddress.ip_address(host)
        except ValueError:
            return False
        return True

    def allowed(self, origin: str, request: web.Request) -> bool:
        """Whether a request from `origin` may change state or open the live channel."""
        origin = origin.lower().rstrip("/")
        return origin == f"{request.scheme}://{request.host}".lower() or origin in self.allowed_origins


def middleware(policy: OriginPolicy, on_refused: Callable[[web.Request, str], Awaitable[None]] | None = None
               ) -> Callable[..., Awaitable[web.StreamResponse]]:
    """Host and Origin checks before the handler; safety headers on every response.

    `on_refused(request, reason)` is told of every state-changing request refused by the Origin
    check (the server reports it to the audit trail and logs it), as a missing CSRF token is.
    """

    @web.middleware
    async def guard(request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]) -> web.StreamResponse:
        try:
            if not policy.host_ok(request):
                raise web.HTTPMisdirectedRequest(text=f"unknown host name {clip(request.host, 100)!r}: add it to servers.hmi.allowed_origins")
            if request.method in UNSAFE_METHODS:
                origin = request.headers.get("Origin")
                reason = None
                if origin is not None and not policy.allowed(origin, request):
                    reason = f"cross-origin request from {clip(origin, 100)} refused"
                elif origin is None and request.headers.get("Sec-Fetch-Site") == "cross-site":
                    reason = "cross-site request refused"
                if reason is not None:
                    if on_refused is not None:
                        await on_refused(request, reason)
                    raise web.HTTPForbidden(text=reason)
            response = await handler(request)
        except web.HTTPException as error:
            if request.path.startswith("/api/") and error.status >= 400:
                # Scripts get JSON errors, like every other answer of the API.
                response = web.json_response({"error": error.text or error.reason}, status=error.status)
                _decorate(request, response)
                return response
            _decorate(request, error)
            raise
        if not response.prepared:
            _decorate(request, response)
        return response

    return guard


def _decorate(request: web.Request, response: web.StreamResponse) -> None:
    for name, value in HEADERS.items():
        response.headers.setdefault(name, value)
    if request.path.startswith("/api/"):
        response.headers.setdefault("Cache-Control", "no-store")
    elif "Cache-Control" not in response.headers:
        response.headers["Cache-Control"] = "no-cache"  # revalidate (ETag): an updated page shows on reload
