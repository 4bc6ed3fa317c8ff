"""Fan-out of live values: subscription groups encoded once, a rate limit per value, clients that never block the others.

- A **group** is every client watching the same set of items at the same rate. Its changes are
  encoded once (JSON, in chunks) into a *frame*, and the same bytes go to each of its clients.
- **Rate limit per value, leading edge**: a changed value goes out at once unless it was sent
  too often lately; then it waits until the rate allows, and goes with its latest value (a
  burst of two is allowed, so a value changing at about the rate with a scan's jitter is never
  held back: `Group`). A sparse change (an operator's write) never waits for a slot, while a
  value that changes every scan is thinned to `rate` updates a second. Frames are at least
  about FRAME_GAP apart (at most ~110 messages a second), so the changes of several scans share one.
- A **client** sends from its own task. Frames offered while it is still writing go into a
  short queue (shared bytes, no copy); beyond MAX_QUEUED bytes the queue is merged into one set
  of names and, when the client is ready, it is sent the *latest* values of those names (caught
  up, never a backlog) and told it was thinned. A client that stays behind longer than
  `drop_after` is dropped (it reconnects by itself and re-synchronises).

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
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import orjson
from aiohttp import WSMsgType, web

from softplc.adapters.hmi.pacing import Pacer
from softplc.adapters.hmi.sessions import Identity
from softplc.core.tags import Quality

log = logging.getLogger(__name__)

QUALITY_CODE = {Quality.GOOD: 0, Quality.UNCERTAIN: 1, Quality.BAD: 2}
CHUNK = 500  # items per message: ~0.5 ms to encode, so a scan due meanwhile is never held up for long
FRAME_GAP = 0.01  # s between two frames of a group: the changes of a 1 ms task's ten scans share one message
# A frame due within this long goes at once: a loop timer wakes 1-2 ms late on a VM, so waiting
# out a gap of a fraction of a millisecond (a 10 ms task's changes, a frame each scan) cost every
# value ~2.5 ms (bench/hmi_live.py: p50 2.7 → 5.1 ms). Frames are then >= 9 ms apart.
FRAME_EARLY = 0.001
MAX_QUEUED = 256 * 1024  # bytes of frames queued for a busy client before they are merged into its latest values


def wire_value(value: Any) -> Any:
    """A value JSON can carry (non-finite floats as text)."""
    if type(value) is float and not math.isfinite(value):
        return "NaN" if value != value else ("Infinity" if value > 0 else "-Infinity")
    return value


class Frame:
    """One message (in chunks) encoded once: its items, and the timestamp of its oldest value."""

    __slots__ = ("chunks", "items", "oldest", "size")

    def __init__(self, chunks: list[bytes], items: list[Any], oldest: float) -> None:
        self.chunks = chunks
        self.items = items  # Tags and expression Items (objects with name, value, quality, timestamp, forced)
        self.oldest = oldest  # timestamp of the oldest value carried (runtime clock, wall seconds); inf: not a change
        self.size = sum(len(chunk) for chunk in chunks)


class Encoder:
    """Turns items into JSON messages of their current values, in chunks that yield in between."""

    def __init__(self, pacer: Pacer) -> None:
        self._pacer = pacer  # each chunk is one turn (pacing.py)
        self.seconds = 0.0  # CPU time spent encoding (diagnostics, benchmarks)
        self.messages = 0

    async def encode(self, kind: str, items: list[Any]) -> Frame:
        """`{"type": kind, "time", "values", ["times"], ["quality"], ["forced"]}` messages for `items`; the last has `"done": true`."""
        chunks: list[bytes] = []
        oldest = math.inf
        for start in range(0, max(len(items), 1), CHUNK):
            async with self._pacer.turn():
                chunk, first = self._chunk(kind, items[start:start + CHUNK], last=start + CHUNK >= len(items))
            chunks.append(chunk)
            oldest = min(oldest, first)
        return Frame(chunks, items, oldest)

    def _chunk(self, kind: str, items: list[Any], *, last: bool) -> tuple[bytes, float]:
        begun = time.thread_time()  # CPU time of the loop's thread: what encoding cost, however busy the machine
        codes, good = QUALITY_CODE, Quality.GOOD
        values: dict[str, Any] = {}
        times: dict[str, float] = {}
        qualities: dict[str, int] = {}
        forced: list[str] = []
        base: float | None = None
        oldest = math.inf
        for item in items:
            name = item.name
            value = item.value
            if type(value) is float and not math.isfinite(value):
                value = wire_value(value)
            values[name] = value
            stamp = item.timestamp
            if base is None:
                base = stamp
            elif stamp != base:
                times[name] = round(stamp, 3)
            if stamp < oldest:
                oldest = stamp
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
        try:
            # orjson writes the same compact UTF-8 JSON ~5x faster than json (float formatting is
            # most of a frame's cost: 0.10 against 0.58 µs per value).
            encoded = orjson.dumps(message)
        except TypeError:  # what it does not take (a numpy scalar, an integer beyond 64 bits): json, as ever
            encoded = json.dumps(message, separators=(",", ":"), ensure_ascii=False).encode()
        self.seconds += time.thread_time() - begun
        self.messages += 1
        return encoded, oldest


class Client:
    """One browser's live connection: its group, and a sender task that only it can hold up."""

    def __init__(self, ws: web.WebSocketResponse, transport: Any, identity: Identity, peer: str, encoder: Encoder,
                 pacer: Pacer, on_sent: Callable[[Frame], None] | None = None) -> None:
        self.ws = ws
        self.transport = transport
        self.identity = identity
        self.peer = peer
        self.group: Group | None = None
        self.last_received = time.monotonic()
        self.behind_since: float | None = None  # real time it fell behind (None: keeping up)
        self.sent_frames = 0
        self.sent_bytes = 0
        self.thinned = 0  # frames merged into later values because the client was too slow to take them
        self.thinned_told = 0  # of those, how many it has been told about
        self.late_told = 0  # its group's late frames it has been told about
        self.queued_bytes = 0
        self._encoder = encoder
        self._pacer = pacer
        self._on_sent = on_sent  # the hub's record of how old a frame's values were when they went out
        self._queue: deque[Frame] = deque()  # frames to send (shared with the group's other clients)
        self._pending: dict[Any, None] = {}  # items of merged frames: their latest values go next
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

    def offer(self, frame: Frame) -> None:
        """The group's latest frame: queue it, or merge it (and the queue) into the latest values if too far behind."""
        if self._full:
            return  # a full snapshot is due anyway
        if not self._busy and not self._queue and not self._pending:
            self._enqueue(frame)
        elif not self._pending and self.queued_bytes + frame.size <= MAX_QUEUED:
            self._enqueue(frame)
            if self.behind_since is None:
                self.behind_since = time.monotonic()
        else:
            pending = self._pending
            for queued in self._queue:
                pending.update(dict.fromkeys(queued.items))
            pending.update(dict.fromkeys(frame.items))
            self.thinned += len(self._queue) + 1
            self._queue.clear()
            self.queued_bytes = 0
            if self.behind_since is None:
                self.behind_since = time.monotonic()
        self._wake.set()

    def _enqueue(self, frame: Frame) -> None:
        self._queue.append(frame)
        self.queued_bytes += frame.size

    def resynchronise(self) -> None:
        """Send the group's full snapshot next (after a (re)subscription)."""
        self._full = True
        self._queue.clear()
        self.queued_bytes = 0
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
                        snapshot = await self.group.snapshot()
                        # Frames offered while it was encoded go after it: they carry changes at
                        # least as new, and any later change comes in a later frame still.
                        self._queue.appendleft(snapshot)
                        self.queued_bytes += snapshot.size
                    while self._queue:
                        frame = self._queue.popleft()
                        self.queued_bytes -= frame.size
                        for chunk in frame.chunks:
                            await self._send(chunk)
                        if self._on_sent is not None:
                            self._on_sent(frame)
                        while self._control:  # a ping must not wait behind a queue of frames
                            await self._send(self._control.pop(0))
                    if self._pending and self.group is not None:
                        members = self.group.members
                        items, self._pending = [item for item in self._pending if item in members], {}
                        self._wake.set()  # go round once more: new changes may have come meanwhile
                        self._enqueue(await self._encoder.encode("update", items))
                    else:
                        self.behind_since = None  # caught up
                finally:
                    self._busy = False
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass  # the connection went away; the WebSocket handler cleans up

    async def _send(self, data: bytes) -> None:
        # Not a turn: writing an encoded frame costs microseconds, and waiting for a slow
        # client's socket to drain must not hold up the others. A due scan cycle goes first;
        # otherwise no extra trip round the loop (ten clients at 100 frames a second: 1,000 trips).
        await self._pacer.clear()
        await self.ws.send_frame(data, WSMsgType.TEXT)
        self.sent_frames += 1
        self.sent_bytes += len(data)

    def abort(self) -> None:
        """Cut the connection at once (a client too slow to read, or gone silent)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.abort()


class Group:
    """Every client watching one set of items at one rate: changes encoded once for all of them.

    The rate limit is per value, leading edge, with a burst of two (the generic cell rate
    algorithm): each item has a theoretical time of its next send (`_due`), one period after the
    later of its last send and its previous due time. A change goes at once if that time is at
    most one period away, else it waits until it is. On average no value is sent more than
    `rate` times a second; a value changing at about the rate, a little early now and then (a
    scan's jitter), is never held back, and a sparse change never waits for a slot.
    """

    def __init__(self, key: tuple[frozenset[str], float], items: Iterable[Any], encoder: Encoder) -> None:
        self.key = key
        self.members_of = key[0]  # the item names
        self.members = frozenset(items)  # the items themselves (Tags, expression Items)
        self.items = sorted(self.members, key=lambda item: item.name)
        self.period = 1.0 / key[1]
        self.clients: set[Client] = set()
        self.task: asyncio.Task[None] | None = None
        self.frames = 0
        self.late = 0  # frames that went out more than a period after their first item was free to go: values thinned
        self._encoder = encoder
        self._ready: dict[Any, None] = {}  # changed items free to go in the next frame
        self._ready_since: float | None = None  # when the first of them was free to go
        self._due: dict[Any, float] = {}  # item → theoretical time (monotonic) of its next send
        self._waiting: dict[int, dict[Any, None]] = {}  # FRAME_GAP slot (time // FRAME_GAP, rounded up) → items free from then
        self._last_frame_at = -math.inf
        self._wake = asyncio.Event()
        self._version = 0  # bumped on every change of one of its items
        self._snapshot: tuple[int, Frame] | None = None

    @property
    def names(self) -> list[str]:
        return [item.name for item in self.items]

    def note(self, items: Iterable[Any], now: float) -> None:
        """Changed items: free to go at once unless sent too often lately (then as soon as the rate allows)."""
        period, due, ready, waiting = self.period, self._due, self._ready, self._waiting
        limit = now + period  # the tolerance: one period, a burst of two
        for item in items:
            next_send = due.get(item, 0.0)
            if next_send <= limit:
                ready[item] = None
            else:
                slot = math.ceil((next_send - period) / FRAME_GAP)
                bucket = waiting.get(slot)
                if bucket is None:
                    bucket = waiting[slot] = {}
                bucket[item] = None
        if ready and self._ready_since is None:
            self._ready_since = now
        self._version += 1
        self._wake.set()

    async def snapshot(self) -> Frame:
        """The whole set's current values, encoded once for every client (re)subscribing meanwhile."""
        cached = self._snapshot
        if cached is not None and cached[0] == self._version:
            return cached[1]
        version = self._version
        frame = await self._encoder.encode("snapshot", self.items)
        frame.oldest = math.inf  # a snapshot's values are as old as they are: no change to time
        self._snapshot = (version, frame)
        return frame

    async def run(self, pacer: Pacer) -> None:
        """Send frames while changes are ready or waiting for the rate to allow them; then rest."""
        try:
            while self.clients:
                now = time.monotonic()
                waiting = self._waiting
                if waiting:
                    for slot in [slot for slot in waiting if slot * FRAME_GAP <= now]:
                        self._ready.update(waiting.pop(slot))
                        if self._ready_since is None:
                            self._ready_since = slot * FRAME_GAP
                if self._ready:
                    gap = self._last_frame_at + FRAME_GAP - now
                    if gap > FRAME_EARLY:
                        await pacer.sleep(gap - FRAME_EARLY)
                        continue
                    await self._frame()
                    continue
                if not waiting:
                    return  # nothing waits: the dispatcher starts this again on the next change
                self._wake.clear()
                delay = max(0.0, min(waiting) * FRAME_GAP - time.monotonic())
                timer = asyncio.get_running_loop().call_later(delay, self._wake.set)
                try:
                    await self._wake.wait()  # a waiting change's time, or a change free to go at once
                finally:
                    timer.cancel()
        finally:
            self.task = None

    async def _frame(self) -> None:
        """Encode what is ready into one frame and offer it to every client."""
        items, self._ready = list(self._ready), {}
        at = self._last_frame_at = time.monotonic()
        if self._ready_since is not None and at - self._ready_since > self.period:
            self.late += 1  # the runtime fell behind: changes of a whole period were merged (its clients are told)
        self._ready_since = None
        due, period = self._due, self.period
        for item in items:
            next_send = due.get(item, 0.0)
            due[item] = (next_send if next_send > at else at) + period
        frame = await self._encoder.encode("update", items)
        self.frames += 1
        for client in list(self.clients):
            client.offer(frame)
