"""Alarms on the live channel: a snapshot when a page asks, then every transition, rate-limited like tags.

A page that shows alarms (the banner on every page, the alarm summary) sends
`{"type": "alarms", "on": true}` on the live WebSocket, again after each reconnection. It gets

    {"type": "alarms", "snapshot": true, "time": T, "alarms": [every alarm that is not normal], "summary": {...}}

and from then on, at most `rate` messages a second (real time, as for tags), the alarms that
changed since the last message (their latest state; a normal one has left the list), the
transitions themselves (for the sound; at most MAX_TRANSITIONS, `dropped` says how many more),
and the summary:

    {"type": "alarms", "time": T, "alarms": [...], "transitions": [{alarm, transition, time, state, previous,
     priority, user, comment}], "dropped": 0, "summary": {active, unacknowledged, shelved, highest_priority, ...}}

It listens to `plant.events` (kind "alarm"): the engine publishes each transition inside the
scan, and the listener only notes it; a message is encoded once, in a turn (pacing.py), and the
same bytes go to every page that asked. A client that does not read its messages is not fed a
backlog: it gets a fresh snapshot once it has caught up. Lists and the summary come from the
`alarms.list` and `alarms.summary` commands, as for every other client of the alarms.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from typing import TYPE_CHECKING, Any

from softplc.adapters.hmi.pacing import Pacer
from softplc.adapters.hmi.wire import dumps
from softplc.core.events import Event, EventBus
from softplc.core.tagdb import Origin

if TYPE_CHECKING:
    from softplc.adapters.hmi.fanout import Client
    from softplc.core.commands import Commands

log = logging.getLogger(__name__)

FEED = Origin("hmi", role=None)  # reads for every page at once: the runtime's own
NOT_NORMAL = ("annunciated", "shelved", "suppressed", "out_of_service")
MAX_TRANSITIONS = 100  # transitions listed in one message (a flood is summarised by `dropped`)
MAX_BACKLOG = 20  # messages a client may have queued before it is resynchronised instead


class AlarmFeed:
    """Pushes alarm snapshots and changes to the live clients that asked for them."""

    def __init__(self, commands: Commands, events: EventBus, pacer: Pacer, wall: Any, *, rate: float) -> None:
        self.commands = commands
        self.events = events
        self.pacer = pacer
        self.wall = wall  # the runtime clock's wall time
        self.interval = 1.0 / rate
        self.clients: set[Client] = set()
        self._stale: set[Client] = set()  # clients to resynchronise once they have caught up
        self._changed: dict[str, Any] = {}  # alarm name → its latest AlarmSnapshot
        self._transitions: deque[dict[str, Any]] = deque(maxlen=MAX_TRANSITIONS)
        self._dropped = 0
        self._wake = asyncio.Event()
        self._next_allowed = 0.0
        self._task: asyncio.Task[None] | None = None
        self._unsubscribe: Any = None
        self.messages = 0  # encoded update messages (diagnostics)

    def start(self) -> None:
        self._unsubscribe = self.events.subscribe(self._heard, kinds=("alarm",))
        self._task = asyncio.create_task(self._run(), name="hmi-alarms")

    async def stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._task is not None:
            self._task.cancel()
            self._task = None
        self.clients.clear()
        self._stale.clear()

    # -- clients ----------------------------------------------------------------------------

    async def join(self, client: Client) -> None:
        """Send `client` the snapshot and follow the alarms for it from now on."""
        self.clients.add(client)
        self._stale.discard(client)
        client.send_encoded(await self._snapshot())

    def leave(self, client: Client) -> None:
        self.clients.discard(client)
        self._stale.discard(client)

    # -- events in ----------------------------------------------------------------------------

    def _heard(self, event: Event) -> None:
        # Called inside the scan: note it, nothing more.
        if not self.clients:
            return
        data = event.data
        snapshot = data.get("alarm")
        self._changed[event.source] = snapshot
        if len(self._transitions) == MAX_TRANSITIONS:
            self._dropped += 1
        self._transitions.append({
            "alarm": event.source, "transition": data.get("transition", ""), "time": event.time,
            "state": getattr(getattr(snapshot, "state", None), "value", ""), "previous": data.get("previous", ""),
            "priority": getattr(getattr(snapshot, "priority", None), "value", ""), "user": data.get("user", ""),
            "comment": data.get("comment", ""),
        })
        self._wake.set()

    # -- messages out ---------------------------------------------------------------------------

    async def _run(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            wait = self._next_allowed - time.monotonic()
            if wait > 0:
                await self.pacer.sleep(wait)  # changes meanwhile join this message
            self._next_allowed = time.monotonic() + self.interval
            changed, self._changed = self._changed, {}
            transitions, dropped = list(self._transitions), self._dropped
            self._transitions.clear()
            self._dropped = 0
            if not self.clients:
                continue
            if changed or transitions:
                await self._send(changed, transitions, dropped)
            await self._resynchronise()

    async def _send(self, changed: dict[str, Any], transitions: list[dict[str, Any]], dropped: int) -> None:
        summary = await self.commands.call("alarms.summary", {}, FEED)
        async with self.pacer.turn():
            message = dumps({"type": "alarms", "time": round(self.wall(), 3), "alarms": [s.to_dict() for s in changed.values()],
                             "transitions": transitions, "dropped": dropped, "summary": summary}).encode()
        self.messages += 1
        for client in list(self.clients):
            if client in self._stale or client.backlog >= MAX_BACKLOG:
                self._stale.add(client)  # it missed this one: a snapshot when it has caught up
            else:
                client.send_encoded(message)

    async def _resynchronise(self) -> None:
        caught_up = [client for client in self._stale if client.backlog == 0 and client in self.clients]
        if not caught_up:
            if self._stale:
                self._wake.set()  # look again at the next turn of the rate limit
            return
        snapshot = await self._snapshot()
        for client in caught_up:
            self._stale.discard(client)
            client.send_encoded(snapshot)
        if self._stale:
            self._wake.set()

    async def _snapshot(self) -> bytes:
        alarms: list[Any] = []
        for state in NOT_NORMAL:
            alarms.extend(await self.commands.call("alarms.list", {"state": state}, FEED))
        summary = await self.commands.call("alarms.summary", {}, FEED)
        async with self.pacer.turn():
            return dumps({"type": "alarms", "snapshot": True, "time": round(self.wall(), 3), "alarms": alarms,
                          "summary": summary}).encode()
