"""Fan-out of live values: subscription groups encoded once, clients that never block the others.

- A **group** is every client watching the same set of items at the same rate. Its changes are
  encoded once (JSON, in chunks) and the same bytes go to each of its clients.
- A **client** sends from its own task. While it is still writing earlier data, new changes are
  not queued: their names are merged into one pending set, and when the client is ready it is
  sent the *latest* values of those names (caught up, never a backlog). A client that stays
  behind longer than `drop_after` is dropped (it reconnects by itself and re-synchronises).

Wire format: `{"type": "update", "time": T, "values": {name: value}, "times": {name: t},
"quality": {name: code}, "forced": [name, ...]}` — `time` is the timestamp (epoch seconds;
simulated under --sim) of the items not listed in `times` (a scan commits its outputs with one
timestamp, so `times` is mostly absent), `quality` lists only the items that are not good (1
uncertain, 2 bad), and `forced` the items that are forced (softplc/core/forcing.py: quality good, but
pinned by an engineer); an item of the message not listed there is not forced.
Encoding a timestamp and a quality per item would double the cost of an update. Non-finite
floats travel as the strings "NaN", "Infinity", "-Infinity" (JSON has no such numbers).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from collections.abc import Callable, Iterable
from typing import Any

from aiohttp import WSMsgType, web

from softplc.adapters.hmi.pacing import Pacer
from softplc.adapters.hmi.sessions import Identity
from softplc.core.tags import Quality

log = logging.getLogger(__name__)

QUALITY_CODE = {Quality.GOOD: 0, Quality.UNCERTAIN: 1, Quality.BAD: 2}
CHUNK = 500  # items per message: ~0.5 ms to encode, so a scan due meanwhile is never held up for long


def wire_value(value: Any) -> Any:
    """A value JSON can carry (non-finite floats as text)."""
    if type(value) is float and not math.isfinite(value):
        return "NaN" if value != value else ("Infinity" if value > 0 else "-Infinity")
    return value


class Encoder:
    """Turns item names into JSON messages of their current values, in chunks that yield in between."""

    def __init__(self, lookup: Callable[[str], Any], pacer: Pacer) -> None:
        self._lookup = lookup  # name → object with value, quality, timestamp (a Tag or an expression Item)
        self._pacer = pacer  # each chunk is one turn (pacing.py)
        self.seconds = 0.0  # CPU time spent encoding (diagnostics, benchmarks)
        self.messages = 0

    async def encode(self, kind: str, names: list[str]) -> list[bytes]:
        """`{"type": kind, "time", "values", ["times"], ["quality"]}` messages for `names`; the last has `"done": true`."""
        chunks: list[bytes] = []
        for start in range(0, max(len(names), 1), CHUNK):
            async with self._pacer.turn():
                chunks.append(self._chunk(kind, names[start:start + CHUNK], last=start + CHUNK >= len(names)))
        return chunks

    def _chunk(self, kind: str, names: list[str], *, last: bool) -> bytes:
        begun = time.thread_time()  # CPU time of the loop's thread: what encoding cost, however busy the machine
        lookup, codes, good = self._lookup, QUALITY_CODE, Quality.GOOD
        values: dict[str, Any] = {}
        times: dict[str, float] = {}
        qualities: dict[str, int] = {}
        forced: list[str] = []
        base: float | None = None
        for name in names:
            item = lookup(name)
            if item is None:
                continue
            value = item.value
            if type(value) is float and not math.isfinite(value):
                value = wire_value(value)
            values[name] = value
            stamp = item.timestamp
            if base is None:
                base = stamp
            elif stamp != base:
                times[name] = round(stamp, 3)
            if item.quality is not good:
                qualities[name] = codes[item.quality]
            if item.forced:
                forced.append(name)
        message: dict[str, Any] = {"type": kind, "time": round(base or 0.0, 3), "values": values}
        if times:
            message["times"] = times
        if qualities:
            message["quality"] = qualities
        if forced:
            message["forced"] = forced
        if last:
            message["done"] = True
        encoded = json.dumps(message, separators=(",", ":"), ensure_ascii=False).encode()
        self.seconds += time.thread_time() - begun
        self.messages += 1
        return encoded


class Client:
    """One browser's live connection: its group, and a sender task that only it can hold up."""

    def __init__(self, ws: web.WebSocketResponse, transport: Any, identity: Identity, peer: str, encoder: Encoder,
                 pacer: Pacer) -> None:
        self.ws = ws
        self.transport = transport
        self.identity = identity
        self.peer = peer
        self.group: Group | None = None
        self.last_received = time.monotonic()
        self.behind_since: float | None = None  # real time it fell behind (None: keeping up)
        self.sent_frames = 0
        self.sent_bytes = 0
        self._encoder = encoder
        self._pacer = pacer
        self._queue: list[bytes] = []  # encoded chunks to send now (shared with the group's other clients)
        self._pending: dict[str, None] = {}  # names changed while busy: their latest values go next
        self._full = False  # the group's whole snapshot goes next (a (re)subscription)
        self._control: list[bytes] = []  # small messages (hello, ping, errors) that go before data
        self._busy = False
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.create_task(self._send_loop(), name=f"hmi-client-{self.peer}")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except (asyncio.CancelledError, Exception):
                pass
            self._task = None

    # -- what to send ---------------------------------------------------------------------------

    def control(self, message: dict[str, Any]) -> None:
        self.send_encoded(json.dumps(message, separators=(",", ":"), ensure_ascii=False).encode())

    def send_encoded(self, data: bytes) -> None:
        """Queue a message encoded once for many clients (alarm events); it goes before tag data."""
        self._control.append(data)
        self._wake.set()

    @property
    def backlog(self) -> int:
        """Messages queued and not yet sent (besides tag data, which never queues up)."""
        return len(self._control)

    def offer(self, chunks: list[bytes], names: Iterable[str]) -> None:
        """The group's latest changes: send these chunks now, or remember the names if still busy."""
        if self._full:
            return  # a full snapshot is due anyway
        if self._busy or self._queue:
            self._pending.update(dict.fromkeys(names))
            if self.behind_since is None:
                self.behind_since = time.monotonic()
        else:
            self._queue = list(chunks)
        self._wake.set()

    def resynchronise(self) -> None:
        """Send the group's full snapshot next (after a (re)subscription)."""
        self._full = True
        self._queue = []
        self._pending = {}
        self._wake.set()

    # -- sending --------------------------------------------------------------------------------

    async def _send_loop(self) -> None:
        ws = self.ws
        try:
            while not ws.closed:
                await self._wake.wait()
                self._wake.clear()
                self._busy = True
                try:
                    while self._control:
                        await self._send(self._control.pop(0))
                    if self._full and self.group is not None:
                        self._full = False
                        self._queue = await self.group.snapshot()
                    for chunk in self._queue:
                        await self._send(chunk)
                    self._queue = []
                    if self._pending and self.group is not None:
                        names, self._pending = list(self._pending), {}
                        self._wake.set()  # go round once more: new changes may have come meanwhile
                        self._queue = await self._encoder.encode("update", [name for name in names if name in self.group.members_of])
                    else:
                        self.behind_since = None  # caught up
                finally:
                    self._busy = False
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass  # the connection went away; the WebSocket handler cleans up

    async def _send(self, data: bytes) -> None:
        # Not a turn: writing an encoded frame costs microseconds, and waiting for a slow
        # client's socket to drain must not hold up the others. A due scan cycle goes first.
        await self._pacer.ready()
        await self.ws.send_frame(data, WSMsgType.TEXT)
        self.sent_frames += 1
        self.sent_bytes += len(data)

    def abort(self) -> None:
        """Cut the connection at once (a client too slow to read, or gone silent)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.abort()


class Group:
    """Every client watching one set of items at one rate: changes encoded once for all of them."""

    def __init__(self, key: tuple[frozenset[str], float], encoder: Encoder) -> None:
        self.key = key
        self.members_of = key[0]  # the item names
        self.names = sorted(key[0])
        self.interval = 1.0 / key[1]
        self.clients: set[Client] = set()
        self.dirty: dict[str, None] = {}
        self.next_allowed = 0.0  # real time of the next allowed update (the rate limit)
        self.task: asyncio.Task[None] | None = None
        self._encoder = encoder
        self._version = 0  # bumped on every change of one of its items
        self._snapshot: tuple[int, list[bytes]] | None = None

    def mark(self, name: str) -> None:
        self.dirty[name] = None
        self._version += 1

    def mark_all(self, names: Iterable[str]) -> None:
        self.dirty.update(dict.fromkeys(names))
        self._version += 1

    async def snapshot(self) -> list[bytes]:
        """The whole set's current values, encoded once for every client (re)subscribing meanwhile."""
        cached = self._snapshot
        if cached is not None and cached[0] == self._version:
            return cached[1]
        version = self._version
        chunks = await self._encoder.encode("snapshot", self.names)
        self._snapshot = (version, chunks)
        return chunks

    async def run(self, pacer: Pacer) -> None:
        """Send the changes, at most one update per interval, until nothing is left."""
        try:
            while self.dirty and self.clients:
                wait = self.next_allowed - time.monotonic()
                if wait > 0:
                    await pacer.sleep(wait)
                names, self.dirty = list(self.dirty), {}
                self.next_allowed = time.monotonic() + self.interval
                chunks = await self._encoder.encode("update", names)
                for client in list(self.clients):
                    client.offer(chunks, names)
        finally:
            self.task = None
