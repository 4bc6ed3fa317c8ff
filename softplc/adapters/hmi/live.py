"""The live channel: one WebSocket per browser at `/api/live`, fed from the tag database's changes.

Protocol (JSON text messages; docs/hmi.md):

    server → {"type": "hello", "instance": ID, "heartbeat": 2.0, "rate": 10, "user": ..., "role": ...}
    client → {"type": "subscribe", "items": ["t01_iBL", "=t01_iBL > 90", ...], "id": 7}   (replaces the set; id optional)
    server → {"type": "subscribed", "id": 7}   when a subscription with an id is applied: the next snapshot is its own
    server → {"type": "snapshot", "time": 1767225600.1, "values": {"t01_iBL": 42.0, ...}, "done": true}
    server → {"type": "update", "time": T, "values": {...}, "times": {...}, "quality": {...}}
             only changed items, sent at once, each value at most `rate` times a second (fanout.py)
    server → {"type": "thinned", "updates": N, "message": ...}   a slow client's updates were merged
    client → {"type": "alarms", "on": true}   alarm snapshot, then alarm changes (alarm_feed.py)
    both   → {"type": "ping"} every `heartbeat` seconds; each side drops a peer silent for 2.5 of them

The scan is never held up: `db.on_change` only hands the list of changed tags to a dispatcher
task, which notes them in the groups that watch them; each group encodes its update once, in
chunks. Each slice of that work is one *turn* of pacing.py: one at a time, never into a scan
cycle due within 5 ms. How late the values go out is recorded (delivery.py).

Pacing (rate limit, heartbeats, slow-client drop) is in real time even under `--sim --speed N`:
it protects the network and the browser, which live in real time. Paced on the simulated clock,
a run at 100x would send 1,000 updates per second to every browser, and one as fast as possible
would flood them (or, idle, never send at all).
"""

from __future__ import annotations

import asyncio
import logging
import math
import secrets
import time
from collections.abc import Sequence
from itertools import chain
from typing import TYPE_CHECKING, Any

from aiohttp import WSMsgType, web

from softplc.adapters.hmi.delivery import DeliveryRecord
from softplc.adapters.hmi.expressions import ExpressionTable
from softplc.adapters.hmi.fanout import Client, Encoder, Frame, Group
from softplc.adapters.hmi.pacing import Pacer
from softplc.adapters.hmi.sessions import Identity
from softplc.adapters.hmi.untrusted import BadJson, clip, loads, shown
from softplc.core.clock import Clock
from softplc.core.tagdb import TagDatabase
from softplc.core.tags import Tag
from softplc.util.peers import PeerLog, peer_host
from softplc.util.tasks import within

if TYPE_CHECKING:
    from softplc.adapters.hmi.alarm_feed import AlarmFeed
    from softplc.adapters.hmi.security import OriginPolicy
    from softplc.adapters.hmi.sessions import Sessions

log = logging.getLogger(__name__)

MAX_ITEMS = 20_000  # items in one subscription
MAX_MESSAGE = 2 * 1024 * 1024  # bytes of one client message (a subscription of 20,000 names fits)
SUBSCRIBE_INTERVAL = 0.1  # s: a client changing its subscription faster gets the last one it asked for
SILENCE = 2.5  # heartbeats without a word before a peer is taken for gone
DISPATCH_SLICE = 1000  # changed tags sorted into groups per turn (~0.3 ms)
TRY_AGAIN_LATER = 1013  # WebSocket close code of a refused connection (RFC 6455 registry: "Try Again Later")
MAX_CLOSE_REASON = 123  # bytes of a close frame's reason
MAX_ID = 2**53 - 1  # a subscription's id: a whole number JavaScript counts exactly


def _subscription_id(value: Any) -> bool:
    """Absent, or a whole number a page can count to (not a bool, a float or text)."""
    return value is None or (type(value) is int and 0 <= value <= MAX_ID)


class Hub:
    """Every live client, grouped by what they watch; pushes changed values to them."""

    def __init__(self, db: TagDatabase, expressions: ExpressionTable, clock: Clock, *, rate: float, heartbeat: float,
                 max_clients: int, max_clients_per_address: int | None = None, drop_after: float | None = None,
                 pacer: Pacer | None = None) -> None:
        self.db = db
        self.expressions = expressions
        self.clock = clock
        self.rate = rate
        self.heartbeat = heartbeat
        self.max_clients = max_clients
        self.max_clients_per_address = max_clients_per_address or max_clients
        self._holders: dict[tuple[str, str], int] = {}  # ("address", host) or ("login", token) → live connections
        self.drop_after = drop_after if drop_after is not None else max(10.0, 5 * heartbeat)
        self.instance = secrets.token_hex(8)  # a new one per start: pages notice the runtime restarted
        self.clients: set[Client] = set()
        self.groups: dict[tuple[frozenset[str], float], Group] = {}
        self.pacer = pacer or Pacer(clock)
        self.encoder = Encoder(self.pacer)
        self.delivery = DeliveryRecord()
        self._incoming: list[Sequence[Tag]] = []
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._unsubscribe: Any = None
        self.peer_log = PeerLog(log, service="HMI")
        self.alarm_feed: AlarmFeed | None = None  # set by the server when the runtime has alarms
        self.dropped = 0  # clients dropped for being too slow or silent
        self.dispatch_seconds = 0.0

    # -- lifecycle ----------------------------------------------------------------------------

    def start(self) -> None:
        self._unsubscribe = self.db.on_change(self._changed)
        self._tasks = [asyncio.create_task(self._dispatch(), name="hmi-dispatch"),
                       asyncio.create_task(self._heartbeats(), name="hmi-heartbeats")]

    async def stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        for task in self._tasks:
            task.cancel()
        for client in list(self.clients):
            try:
                await within(1.0, client.ws.close(code=1001, message=b"runtime stopping"))
            except (asyncio.TimeoutError, ConnectionError, RuntimeError):
                client.abort()
            await client.stop()
        for group in self.groups.values():
            if group.task is not None:
                group.task.cancel()
        self.clients.clear()
        self.groups.clear()

    def stats(self, since: float = 0.0) -> dict[str, Any]:
        """Figures of the live channel; `delivery`: the ages of the values sent since `since` (delivery.py)."""
        return {
            "clients": len(self.clients),
            "groups": len(self.groups),
            "frames_sent": sum(client.sent_frames for client in self.clients),
            "thinned": sum(client.thinned for client in self.clients),
            "delivery": self.delivery.summary(since),
            "bytes_sent": sum(client.sent_bytes for client in self.clients),
            "messages_encoded": self.encoder.messages,
            "encode_seconds": round(self.encoder.seconds, 4),
            "dispatch_seconds": round(self.dispatch_seconds, 4),
            "dropped": self.dropped,
            "behind": sum(1 for client in self.clients if client.behind_since is not None),
        }

    # -- changes in -----------------------------------------------------------------------------

    def _changed(self, tags: Sequence[Tag]) -> None:
        # Called inside the scan cycle: hand the list over, nothing more.
        self._incoming.append(tags)
        self._wake.set()

    async def _dispatch(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            batches, self._incoming = self._incoming, []
            if not self.groups:  # no browser watches anything: no turns to take
                self.expressions.stale = True  # ... but the expressions missed these changes
                continue
            # The batches of several scans (each commits its own) share a turn: fewer, fuller turns.
            changed = batches[0] if len(batches) == 1 else list(chain.from_iterable(batches))
            for start in range(0, len(changed), DISPATCH_SLICE):
                async with self.pacer.turn():
                    self._sort(changed[start:start + DISPATCH_SLICE])

    def _sort(self, tags: Sequence[Tag]) -> None:
        """Note the changed tags (and the expressions that read them) in the groups that watch them.

        Set intersections of the objects themselves: C speed, not a Python loop per tag; the
        per-value rate limit (`Group.note`) then loops over what each group watches only.
        """
        begun = time.thread_time()
        changed: set[Any] = set(tags)
        changed.update(self.expressions.changed(changed))
        now = time.monotonic()
        for group in self.groups.values():
            watched = changed & group.members
            if watched:
                group.note(watched, now)
                if group.task is None and group.clients:
                    group.task = asyncio.create_task(group.run(self.pacer), name="hmi-group")
        self.dispatch_seconds += time.thread_time() - begun

    def _sent(self, frame: Frame) -> None:
        """A client's frame went out: how old was its oldest value (the server's part of the latency)."""
        if frame.oldest != math.inf and not self.clock.simulated:
            self.delivery.add(self.clock.wall() - frame.oldest)

    def _item(self, name: str) -> Any:
        tag = self.db.get(name)
        return tag if tag is not None else self.expressions.get(name)

    # -- clients --------------------------------------------------------------------------------

    def subscribe(self, client: Client, names: list[str]) -> list[str]:
        """Move the client to the group of `names` (known ones); returns the unknown ones."""
        if self.expressions.stale:
            self.expressions.refresh()  # tags changed while nobody watched: the snapshot must be current
        found = {name: self._item(name) for name in names}
        unknown = [name for name, item in found.items() if item is None]
        key = (frozenset(name for name, item in found.items() if item is not None), self.rate)
        self._leave(client)
        group = self.groups.get(key)
        if group is None:
            group = self.groups[key] = Group(key, (item for item in found.values() if item is not None), self.encoder)
        group.clients.add(client)
        client.group = group
        client.late_told = group.late  # told of its new group's lateness from now on
        client.resynchronise()
        return unknown

    def _leave(self, client: Client) -> None:
        group = client.group
        client.group = None
        if group is None:
            return
        group.clients.discard(client)
        if not group.clients:
            del self.groups[group.key]
            if group.task is not None:
                group.task.cancel()

    async def _heartbeats(self) -> None:
        """Ping every client each heartbeat; drop the silent and the hopelessly slow ones (checked every second)."""
        tick = min(self.heartbeat, 1.0)
        last_ping = time.monotonic()
        while True:
            await self.pacer.sleep(tick)
            now = time.monotonic()
            ping = now - last_ping >= self.heartbeat - tick / 2
            if ping:
                last_ping = now
            for client in list(self.clients):
                if now - client.last_received > SILENCE * self.heartbeat:
                    self._drop(client, f"silent for {SILENCE * self.heartbeat:.1f} s")
                elif client.behind_since is not None and now - client.behind_since > self.drop_after:
                    self._drop(client, f"more than {self.drop_after:.0f} s behind (too slow to read its updates)")
                elif ping:
                    client.control({"type": "ping"})
                self._tell_thinned(client)

    @staticmethod
    def _tell_thinned(client: Client) -> None:
        """Tell a client, at most once a tick, that it got fewer updates than the rate: never thinned silently."""
        late = client.group.late if client.group is not None else 0
        merged, behind = client.thinned - client.thinned_told, late - client.late_told
        if merged <= 0 and behind <= 0:
            client.late_told = late  # a new group's count
            return
        client.thinned_told, client.late_told = client.thinned, late
        why = (f"this connection could not take every update: {merged} were merged into later ones" if merged > 0 else
               f"the runtime could not send every change in time: {behind} updates were late and merged")
        client.control({"type": "thinned", "updates": merged, "late": max(behind, 0),
                        "message": f"{why} (each value shown is still the latest)"})

    def _drop(self, client: Client, why: str) -> None:
        self.dropped += 1
        self.peer_log.warning(peer_host(client.peer), "dropped live clients", "HMI: live client %s dropped: %s", client.peer, why)
        client.abort()

    # -- the WebSocket endpoint -----------------------------------------------------------------

    async def handle(self, request: web.Request, identity: Identity, origins: OriginPolicy, sessions: Sessions) -> web.StreamResponse:
        """GET /api/live: checks done by the caller (identity); here the Origin and the connection limits."""
        origin = request.headers.get("Origin")
        peer = peer_host(request.remote)
        if origin is not None and not origins.allowed(origin, request):
            self.peer_log.warning(peer, "refused live origins", "HMI: live connection from %s refused: origin %s",
                                  request.remote, clip(origin, 100), detail=clip(origin, 100))
            raise web.HTTPForbidden(text="cross-origin WebSocket refused")
        # A visitor without a login counts by address, a login by itself: an anonymous flood from
        # this computer cannot lock out an operator who logs in.
        holder = ("login", identity.session.token) if identity.session is not None else ("address", peer)
        refusal = None
        if len(self.clients) >= self.max_clients:
            plural = "s" if self.max_clients != 1 else ""
            refusal = f"the runtime serves at most {self.max_clients} live connection{plural} at once; try again later"
        elif self._holders.get(holder, 0) >= self.max_clients_per_address:
            refusal = (f"too many live connections from {clip(peer, 45)} (at most {self.max_clients_per_address} "
                       f"{'per login' if identity.session is not None else 'per address without a login'}): close other tabs")
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE, compress=False, autoping=True)
        await ws.prepare(request)
        if refusal is not None:
            # Accepted only to be closed with the reason: a browser never sees the body of a refused
            # handshake (it reports 1006, "connection lost"), but it does see a close frame's reason.
            self.peer_log.warning(peer, "refused live connections", "HMI: live connection from %s refused: %s", peer, refusal)
            reason = refusal.encode()[:MAX_CLOSE_REASON].decode("utf-8", "ignore").encode()  # whole characters only
            await ws.close(code=TRY_AGAIN_LATER, message=reason)
            return ws
        self._holders[holder] = self._holders.get(holder, 0) + 1
        try:
            return await self._serve(request, ws, identity)
        finally:
            left = self._holders.pop(holder) - 1
            if left:
                self._holders[holder] = left

    async def _serve(self, request: web.Request, ws: web.WebSocketResponse, identity: Identity) -> web.WebSocketResponse:
        client = Client(ws, request.transport, identity, str(request.remote), self.encoder, self.pacer, self._sent)
        self.clients.add(client)
        client.start()
        client.control({"type": "hello", "instance": self.instance, "heartbeat": self.heartbeat, "rate": self.rate,
                        "user": identity.user, "role": identity.role.value})
        subscriber = _Subscriber(self, client)
        try:
            async for message in ws:
                client.last_received = time.monotonic()
                if message.type is not WSMsgType.TEXT:
                    continue
                subscriber.handle(message.data)
        finally:
            subscriber.cancel()
            if self.alarm_feed is not None:
                self.alarm_feed.leave(client)
            self._leave(client)
            self.clients.discard(client)
            await client.stop()
        return ws


class _Subscriber:
    """A client's requests: at most one subscription change per SUBSCRIBE_INTERVAL (the last wins)."""

    def __init__(self, hub: Hub, client: Client) -> None:
        self.hub = hub
        self.client = client
        self._wanted: list[str] | None = None
        self._wanted_id: int | None = None  # the client's number of that subscription, echoed when applied
        self._timer: asyncio.TimerHandle | None = None
        self._last = 0.0
        self._joining: asyncio.Task[None] | None = None

    def handle(self, text: str) -> None:
        try:
            message = loads(text)
        except BadJson as error:
            self.client.control({"type": "error", "message": f"the message is {error}"})
            return
        kind = message.get("type") if isinstance(message, dict) else None
        if kind == "ping":
            self.client.control({"type": "pong"})
        elif kind == "subscribe":
            items = message.get("items")
            if not isinstance(items, list) or not all(isinstance(item, str) for item in items):
                self.client.control({"type": "error", "message": "subscribe needs 'items': a list of names"})
            elif len(items) > MAX_ITEMS:
                self.client.control({"type": "error", "message": f"at most {MAX_ITEMS} items in one subscription"})
            elif not _subscription_id(message.get("id")):
                self.client.control({"type": "error", "message": f"subscribe's 'id' must be a whole number from 0 to {MAX_ID}"})
            else:
                self._wanted = list(dict.fromkeys(items))
                self._wanted_id = message.get("id")
                self._schedule()
        elif kind == "alarms":
            self._alarms(message.get("on", True))
        elif kind != "pong":
            self.client.control({"type": "error", "message": f"unknown message type {shown(kind)!r}"})

    def _alarms(self, on: Any) -> None:
        feed = self.hub.alarm_feed
        if feed is None:
            self.client.control({"type": "error", "message": "this runtime has no alarms"})
        elif on is False:
            feed.leave(self.client)
        elif self.client not in feed.clients and (self._joining is None or self._joining.done()):
            self._joining = asyncio.create_task(feed.join(self.client), name="hmi-alarms-join")

    def _schedule(self) -> None:
        if self._timer is not None:
            return
        delay = self._last + SUBSCRIBE_INTERVAL - time.monotonic()
        self._timer = asyncio.get_running_loop().call_later(max(0.0, delay), self._apply)

    def _apply(self) -> None:
        self._timer = None
        wanted, self._wanted = self._wanted, None
        if wanted is None or self.client.ws.closed:
            return
        self._last = time.monotonic()
        unknown = self.hub.subscribe(self.client, wanted)
        if self._wanted_id is not None:
            # Queued with the resynchronisation, so it goes out after any snapshot of the previous set
            # still being sent and before this set's: a page that subscribed twice in quick
            # succession takes only the snapshot after it for its current set.
            self.client.control({"type": "subscribed", "id": self._wanted_id})
        if unknown:
            self.client.control({"type": "unknown", "items": [clip(name) for name in unknown[:100]], "count": len(unknown)})

    def cancel(self) -> None:
        if self._joining is not None:
            self._joining.cancel()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
