"""Logins of the HMI: the OPC UA users file, session cookies and CSRF tokens.

- A login is checked by `softplc.security.logins.PasswordLogins` (the same code as OPC UA logins: hashed
  in a worker thread, throttled per address and user name, failures logged rate-limited).
- A session is a random 256-bit token in an HttpOnly, SameSite=Strict cookie (Secure, with the
  `__Host-` prefix, under TLS), named after the port so two runtimes on one host keep theirs.
  Sessions live in memory: a restarted runtime asks for the login again.
- Every state-changing request carries the session's CSRF token in `X-CSRF-Token` (a page of
  another site can neither read the token nor set the header without a CORS preflight we never
  grant); the Origin check in `security.py` comes on top.
- The role is read from the users file on every request, so removing a user or changing a role
  takes effect at once. A visitor without a session is the anonymous viewer, or refused.
- Expiry uses real time, not the runtime clock: under `--sim` a simulated hour passes in seconds.
"""

from __future__ import annotations

import hmac
import secrets
import time
from collections.abc import Callable
from dataclasses import dataclass

from aiohttp import web

from softplc.core.roles import Role
from softplc.security.logins import PasswordLogins
from softplc.security.users import UserStore

CSRF_HEADER = "X-CSRF-Token"
MAX_SESSIONS = 1000  # beyond this the least recently used session is forgotten


@dataclass
class Session:
    """One logged-in browser (or script)."""

    token: str
    user: str
    csrf: str
    created: float
    seen: float


@dataclass(frozen=True)
class Identity:
    """Who is asking: a logged-in user with the role the users file gives now, or the anonymous viewer."""

    user: str
    role: Role
    session: Session | None = None

    @property
    def anonymous(self) -> bool:
        return self.session is None


class Sessions:
    """The HMI's sessions: login, logout, who a request is, and its CSRF token."""

    def __init__(self, users: UserStore, logins: PasswordLogins, *, anonymous_role: Role | None, timeout: float,
                 secure: bool, clock: Callable[[], float] = time.monotonic) -> None:
        self.users = users
        self.logins = logins
        self.anonymous_role = anonymous_role
        self.timeout = timeout
        self.secure = secure
        self.clock = clock
        self.cookie_name = "softplc_hmi"
        self._sessions: dict[str, Session] = {}

    def set_port(self, port: int) -> None:
        """Name the cookie after the port: cookies are per host, not per port."""
        self.cookie_name = f"{'__Host-' if self.secure else ''}softplc_hmi_{port}"

    # -- who is asking ------------------------------------------------------------------------

    def identify(self, request: web.Request) -> Identity | None:
        """The request's identity, or None when it must log in first."""
        session = self.session_of(request)
        if session is not None:
            entry = self.users.get(session.user)
            if entry is not None:
                return Identity(entry.name, entry.role, session)
            self._sessions.pop(session.token, None)  # the user was removed from the file
        if self.anonymous_role is not None:
            return Identity("", self.anonymous_role)
        return None

    def session_of(self, request: web.Request) -> Session | None:
        token = request.cookies.get(self.cookie_name)
        if not token:
            return None
        session = self._sessions.get(token)
        if session is None:
            return None
        now = self.clock()
        if now - session.seen > self.timeout:
            del self._sessions[token]
            return None
        session.seen = now
        self.users.refresh()
        return session

    @staticmethod
    def csrf_ok(request: web.Request, identity: Identity) -> bool:
        """Whether a state-changing request carries its session's CSRF token."""
        if identity.session is None:
            return False
        sent = request.headers.get(CSRF_HEADER, "")
        return bool(sent) and hmac.compare_digest(sent.encode(), identity.session.csrf.encode())

    # -- login and logout ---------------------------------------------------------------------

    async def login(self, peer: str, user: str, password: str) -> Session | None:
        """A new session if the password is right (checked off the loop, throttled), else None."""
        if not await self.logins.check(peer, user, password):
            return None
        now = self.clock()
        self._expire(now)
        while len(self._sessions) >= MAX_SESSIONS:
            oldest = min(self._sessions.values(), key=lambda session: session.seen)
            del self._sessions[oldest.token]
        session = Session(secrets.token_urlsafe(32), user, secrets.token_urlsafe(32), now, now)
        self._sessions[session.token] = session
        return session

    def logout(self, session: Session) -> None:
        self._sessions.pop(session.token, None)

    def close(self) -> None:
        self._sessions.clear()
        self.logins.close()

    def set_cookie(self, response: web.StreamResponse, session: Session) -> None:
        # No Max-Age: the cookie ends with the browser; the server forgets the session after `timeout` idle.
        response.set_cookie(self.cookie_name, session.token, path="/", httponly=True, samesite="Strict", secure=self.secure)

    def clear_cookie(self, response: web.StreamResponse) -> None:
        response.del_cookie(self.cookie_name, path="/", samesite="Strict", secure=self.secure, httponly=True)

    def __len__(self) -> int:
        return len(self._sessions)

    def _expire(self, now: float) -> None:
        stale = [token for token, session in self._sessions.items() if now - session.seen > self.timeout]
        for token in stale:
            del self._sessions[token]
