"""Password logins: hashed off the event loop, throttled per peer address and per user name.

asyncua asks the user manager synchronously, inside ActivateSession, on the event loop that
also runs the scan; a password hash there (~0.4 s at OWASP's scrypt cost) would stall every
task. So `GuardedProcessor` (transport.py) decides a password login *before* it hands the
request to asyncua: `PasswordLogins.check` hashes in one dedicated worker thread
(hashlib.scrypt releases the GIL) and remembers a success, which the user manager's
synchronous `get_user` then only looks up. A refused login never reaches asyncua: the
processor answers BadUserAccessDenied itself.

- One hash at a time, in one thread: a flood of logins costs at most one core and one
  scrypt's memory (~128 MB), never the loop. Each peer address has at most one hash queued,
  so a flooding peer delays another peer's login by one hash at most per flooding peer.
- A success is remembered for the process's lifetime (keyed by an HMAC under a random
  per-process key, never the password), so each user pays the hash once, and a remembered
  login is never throttled.
- Failures are counted over the last `WINDOW` seconds (a hash under way counts as one); a
  login beyond any of these limits is refused without hashing:
  the same user name from the same peer address (5), any user name from one peer address
  (20: password spraying), one user name from any peer (20: distributed guessing). Failures on
  user A from another peer never refuse user B.
- Identical credentials being checked already share that check (clients starting together).
- Lines about failures are rate-limited per peer (`peers.PeerLog`).
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import logging
import secrets
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from softplc.security.passwords import dummy_hash, verify_password
from softplc.util.peers import PeerLog

if TYPE_CHECKING:
    from softplc.security.users import UserEntry, UserStore

log = logging.getLogger(__name__)

WINDOW = 60.0  # seconds over which failed logins are counted
FAILURES_PER_PEER_AND_USER = 5
FAILURES_PER_PEER = 20
FAILURES_PER_USER = 20
MAX_CHECKS_WAITING = 64  # beyond this many logins waiting for the hashing thread, refuse at once
MAX_REMEMBERED = 1000


@dataclass
class _Turn:
    """The hashing turn of one peer address: one hash at a time."""

    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    waiting: int = 0


class LoginThrottle:
    """Counts failed (and ongoing) password checks per peer, per user name and per both."""

    def __init__(self, window: float = WINDOW, clock: Callable[[], float] = time.monotonic) -> None:
        self.window = window
        self.clock = clock  # real time: attackers do not wait for the PLC's simulated clock
        self._failures: dict[tuple[str, str], deque[float]] = {}
        self._ongoing: dict[tuple[str, str], int] = {}

    @staticmethod
    def _keys(peer: str, user: str) -> tuple[tuple[tuple[str, str], int, str], ...]:
        return (
            (("peer+user", f"{peer}\0{user}"), FAILURES_PER_PEER_AND_USER, "this user from this address"),
            (("peer", peer), FAILURES_PER_PEER, "this address"),
            (("user", user), FAILURES_PER_USER, "this user"),
        )

    def refusal(self, peer: str, user: str) -> str | None:
        """Why a check of `user` from `peer` must not be hashed now, or None if it may."""
        now = self.clock()
        for key, limit, what in self._keys(peer, user):
            if self._count(key, now) + self._ongoing.get(key, 0) >= limit:
                return f"{limit} failed logins of {what} within {self.window:.0f} s"
        return None

    def started(self, peer: str, user: str) -> None:
        for key, _, _ in self._keys(peer, user):
            self._ongoing[key] = self._ongoing.get(key, 0) + 1

    def finished(self, peer: str, user: str, failed: bool) -> None:
        now = self.clock()
        for key, _, _ in self._keys(peer, user):
            left = self._ongoing.get(key, 0) - 1
            if left > 0:
                self._ongoing[key] = left
            else:
                self._ongoing.pop(key, None)
            if failed:
                self._failures.setdefault(key, deque()).append(now)

    def _count(self, key: tuple[str, str], now: float) -> int:
        times = self._failures.get(key)
        if times is None:
            return 0
        while times and now - times[0] > self.window:
            times.popleft()
        if not times:
            del self._failures[key]
            return 0
        return len(times)


def _is_text(value: str) -> bool:
    """Whether `value` is valid Unicode text (no lone surrogates: it encodes to UTF-8)."""
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _shown(name: str, limit: int = 64) -> str:
    """A client's user name for a log line: undecodable bytes as \\xNN, at most `limit` characters."""
    try:
        raw = name.encode("utf-8", "surrogateescape")  # the bytes the client sent, when asyncua decoded them
    except UnicodeEncodeError:
        raw = name.encode("utf-8", "backslashreplace")  # lone surrogates of another origin (JSON \udXXX)
    shown = raw.decode("utf-8", "backslashreplace")
    return "'" + (shown if len(shown) <= limit else shown[:limit] + "…") + "'"


class PasswordLogins:
    """Decides password logins against a UserStore, off the event loop (see the module docstring)."""

    def __init__(self, store: UserStore, throttle: LoginThrottle | None = None, *, service: str = "OPC UA") -> None:
        """`service` names the server in log lines ("OPC UA", "HMI")."""
        self.store = store
        self.throttle = throttle or LoginThrottle()
        self.service = service
        self.peer_log = PeerLog(log, service=service)
        self._key = secrets.token_bytes(32)
        self._remembered: dict[bytes, tuple[str, str]] = {}  # HMAC of the credentials → (name, hash it matched)
        self._checks: dict[bytes, asyncio.Task[bool]] = {}  # credentials being hashed now
        self._turns: dict[str, _Turn] = {}
        self._executor: ThreadPoolExecutor | None = None
        self.hashed = 0  # password hashes computed (diagnostics, tests)

    def decided(self, name: str, password: str) -> UserEntry | None:
        """The user, if these credentials were found correct (by `check`) for its current hash."""
        entry = self.store.get(name)
        if entry is None or not entry.password_hash:
            return None
        remembered = self._remembered.get(self._token(name, password))
        return entry if remembered == (entry.name, entry.password_hash) else None

    async def check(self, peer: str, name: str, password: str) -> bool:
        """Whether `name`/`password` from address `peer` may log in; hashes in the worker thread."""
        if not (_is_text(name) and _is_text(password)):
            # Bytes that are not UTF-8 (an OPC UA String decoded with surrogateescape) or lone
            # surrogates (JSON): nobody's name or password. Refused before hashing or throttling,
            # and said once per peer and interval however often it is sent.
            self.peer_log.warning(peer, "logins not in UTF-8", "%s: login from %s refused: its user name or password is not valid UTF-8 (user name %s)",
                                  self.service, peer, _shown(name), detail=_shown(name))
            return False
        self.store.refresh()
        if self.decided(name, password) is not None:
            return True
        token = self._token(name, password)
        check = self._checks.get(token)
        if check is None:
            reason = self.throttle.refusal(peer, name)
            if reason is None and len(self._checks) >= MAX_CHECKS_WAITING:
                reason = f"{MAX_CHECKS_WAITING} logins already waiting to be checked"
            if reason is not None:
                self.peer_log.warning(peer, "refused logins", "%s: login of %r from %s refused without checking: %s",
                                      self.service, name, peer, reason, detail=repr(name))
                return False
            entry = self.store.get(name)
            stored = entry.password_hash if entry is not None and entry.password_hash else None
            # An unknown name is checked against a made-up hash of the same cost: timing tells nothing.
            check = asyncio.ensure_future(self._hash(peer, name, token, password, stored or dummy_hash()))
            self._checks[token] = check
            self.throttle.started(peer, name)  # counted from now, so checks queued behind it see it
            check.add_done_callback(lambda done: self._finished(done, peer, name, token))
        correct = await asyncio.shield(check)
        if not correct:
            self.peer_log.warning(peer, "failed logins", "%s: failed login for user %r from %s", self.service, name, peer, detail=repr(name))
        return correct

    def _finished(self, check: asyncio.Task[bool], peer: str, name: str, token: bytes) -> None:
        self._checks.pop(token, None)
        correct = not check.cancelled() and check.exception() is None and check.result()
        self.throttle.finished(peer, name, failed=not correct)

    async def _hash(self, peer: str, name: str, token: bytes, password: str, stored: str) -> bool:
        turn = self._turns.setdefault(peer, _Turn())
        turn.waiting += 1
        try:
            async with turn.lock:
                loop = asyncio.get_running_loop()
                correct = await loop.run_in_executor(self._worker(), verify_password, password, stored)
                self.hashed += 1
        except RuntimeError:  # the server is stopping: no more hashing
            return False
        finally:
            turn.waiting -= 1
            if turn.waiting == 0 and self._turns.get(peer) is turn:
                del self._turns[peer]
        entry = self.store.get(name)
        if not correct or entry is None or entry.password_hash != stored:
            return False
        while len(self._remembered) >= MAX_REMEMBERED:
            del self._remembered[next(iter(self._remembered))]
        self._remembered[token] = (entry.name, stored)
        log.info("%s: user %r logged in (%s) from %s", self.service, entry.name, entry.role.value, peer)
        return True

    def _worker(self) -> ThreadPoolExecutor:
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"softplc-{self.service.lower().replace(' ', '')}-login")
        return self._executor

    def _token(self, name: str, password: str) -> bytes:
        return hmac.new(self._key, f"{name}\0{password}".encode(), hashlib.sha256).digest()

    def close(self) -> None:
        """Stop the hashing thread (a hash under way finishes on its own)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
