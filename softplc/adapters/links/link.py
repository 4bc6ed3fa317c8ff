"""One link to a remote controller: connect, exchange, reconnect with backoff; its tags' quality and its writes out.

A protocol (`OpcuaLink`, `ModbusLink`) implements `connect`, `exchange` (runs until the
connection fails), `write` and `close`; it hands what it reads to `received` and says when the
remote answered at all (`answered`). Everything else is here, the same for both:

- the reconnect loop: after a failure the link waits 0.5 s, then twice as long at each failure,
  up to `backoff_max`, on the plant's clock;
- the watchdog: no data for 2x the period makes the bound tags UNCERTAIN (state `late`), 5x BAD;
  a link that is down makes them BAD at once;
- writes out: changes of `out` and `both` tags are sent in one request per batch (the latest value
  of each tag), after the remote's own value of a `both` tag is not echoed back to it;
- the `_sys.links.NAME.*` tags.
"""

from __future__ import annotations

import asyncio
import enum
import logging
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any

from softplc.adapters.links.quality import BoundTag, TagPublisher
from softplc.adapters.links.section import PREFIX
from softplc.adapters.links.settings import Binding, LinkSettings
from softplc.core.commands import CommandRefused
from softplc.core.plant import Plant
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality, Tag

log = logging.getLogger(__name__)

WRITE_COMMAND = "links.write"  # a client's write of a bound tag goes out as this command (commands.py)
FIRST_BACKOFF = 0.5
UNCERTAIN_AFTER = 2  # periods without data
BAD_AFTER = 5
MIN_QUALITY_PERIOD = 0.01
LATE_LOG_INTERVAL = 60.0  # s: a link that keeps going late is logged once a minute, not at each episode
_UNSEEN = object()  # a tag not reported to the link yet


class LinkError(Exception):
    """The connection failed or the remote broke the protocol; the message says why, for the person reading it."""


class LinkState(enum.Enum):
    CONNECTING = "connecting"
    UP = "up"
    LATE = "late"  # connected, but no data for 2x the period
    DOWN = "down"


class Link(ABC):
    """What every link does; a protocol fills in the abstract methods (see the module docstring)."""

    def __init__(self, settings: LinkSettings, plant: Plant) -> None:
        self.settings = settings
        self.name = settings.name
        self.plant = plant
        self.clock = plant.clock
        self.db = plant.tags
        self.origin = Origin(f"link:{settings.name}", peer=settings.address, role=None)
        self.bound = {binding.tag.name: BoundTag(binding) for binding in settings.bindings}
        self.readers = [bound for bound in self.bound.values() if bound.binding.direction.reads]
        self.publisher = TagPublisher(self.name, self.db, self.origin)
        self.state = LinkState.CONNECTING
        self.connected = False
        self.error = ""
        self.last_data: float | None = None
        self.reconnects = 0
        self.connections = 0
        self.attempts = 0  # connections tried
        self.requests = 0  # requests sent to the remote (reads, writes, heartbeats)
        self.round_trip = 0.0  # seconds
        self.writes = {"ok": 0, "refused": 0, "failed": 0}
        self.first_attempt = asyncio.Event()
        self._pending: dict[str, Any] = {}  # tag → the latest local value to send
        self._local: dict[str, Any] = {}  # tag → its local value when last reported (a report may be of its quality alone)
        self.client_writes: dict[str, tuple[Any, Origin]] = {}  # tag → (value, origin) of a client's write not sent yet
        self._expect: dict[str, tuple[Any, float]] = {}  # both-tag → (value sent, until when a different remote value is stale)
        self._held: dict[str, Any] = {}  # both-tag → the remote's value received while expecting our write's echo
        self._flushing: asyncio.Task[None] | None = None
        self._wake = asyncio.Event()
        self._sys: dict[str, Any] = {}
        self._down_logged = False
        self._late_logged: float | None = None

    # -- what a protocol implements -------------------------------------------------------

    @abstractmethod
    async def connect(self) -> None:
        """Open the connection and prepare the exchange; raise LinkError."""

    @abstractmethod
    async def exchange(self) -> None:
        """Read (poll or subscribe) until the connection fails: raise LinkError then."""

    @abstractmethod
    async def write(self, items: Sequence[tuple[BoundTag, Any]]) -> list[str | None]:
        """Send values in as few requests as the protocol allows; per item None (taken) or the remote's refusal. Raise LinkError."""

    @abstractmethod
    async def close(self) -> None: ...

    def binding_problems(self) -> list[tuple[Binding, str]]:
        """Bindings the remote cannot serve (found at connect: a missing node, another type)."""
        return []

    # -- running ------------------------------------------------------------------------

    async def run(self) -> None:
        """Connect, exchange, and reconnect with backoff, for the plant's lifetime."""
        backoff = FIRST_BACKOFF
        watchdog = asyncio.ensure_future(self._watch())
        try:
            while True:
                try:
                    if self.state is not LinkState.DOWN:  # a retry stays "down" until it succeeds
                        self._set_state(LinkState.CONNECTING)
                    self.attempts += 1
                    await self.connect()
                    self._connected()
                    backoff = FIRST_BACKOFF
                    self.first_attempt.set()
                    await self.exchange()
                    raise LinkError("the exchange ended")
                except LinkError as error:
                    self._down(str(error))
                except OSError as error:
                    self._down(f"connection failed: {error}")
                finally:
                    self.first_attempt.set()
                    await self._close_quietly()
                await self.clock.sleep(backoff)
                backoff = min(backoff * 2, self.settings.backoff_max)
        finally:
            watchdog.cancel()
            if self._flushing is not None:
                self._flushing.cancel()

    def _connected(self) -> None:
        if self.connections:
            self.reconnects += 1
        self.connections += 1
        self.connected = True
        self.error = ""
        self.last_data = self.clock.now()
        self._down_logged = False
        log.info("link %s: connected to %s", self.name, self.settings.address)
        self._set_state(LinkState.UP)
        self._publish_all()
        # The remote takes every `out` tag's value at once; `both` tags take the remote's.
        for bound in self.bound.values():
            if bound.binding.direction.writes and not bound.binding.direction.reads:
                self._pending[bound.name] = self.db.value(bound.name)
        self._schedule_flush()

    def _down(self, reason: str) -> None:
        self.connected = False
        self.error = reason
        self._set_state(LinkState.DOWN)
        if not self._down_logged:  # once per outage, not at every attempt to reconnect
            log.warning("link %s to %s is down: %s (reconnecting with backoff)", self.name, self.settings.address, reason)
            self._down_logged = True
        self._publish_all()

    async def _close_quietly(self) -> None:
        try:
            await self.close()
        except Exception as error:  # closing a broken connection may fail in any way; it is gone either way
            log.debug("link %s: closing: %r", self.name, error)

    # -- data in ------------------------------------------------------------------------

    def answered(self, round_trip: float | None = None) -> None:
        """The remote answered (data, a keep-alive, a heartbeat): the link is alive now."""
        self.last_data = self.clock.now()
        if round_trip is not None:
            self.round_trip = round_trip
        if self.state is LinkState.LATE:
            self.error = ""
            self._set_state(LinkState.UP)
            self._publish_all()

    def received(self, changed: list[BoundTag]) -> None:
        """Journal the bound tags whose remote value or verdict changed (the protocol updated them)."""
        if self._expect:
            now = self.clock.now()
            for bound in changed:
                expected = self._expect.get(bound.name)
                if expected is None:
                    continue
                value, until = expected
                if bound.value == value or now > until:
                    del self._expect[bound.name]
                    self._held.pop(bound.name, None)
                else:  # a value from before our write, still on its way: kept aside until the write's echo (or the window's end)
                    self._held[bound.name] = bound.value
                    bound.value = value
        if not self.connected:
            return  # read while connecting: published all at once when the link is up
        self.publisher.publish(changed, self.health())
        self._update_sys()

    def _expecting(self, items: Sequence[tuple[BoundTag, Any]]) -> None:
        """Before sending: a `both` tag's remote values older than the write are not taken for its answer."""
        until = self.clock.now() + UNCERTAIN_AFTER * self.settings.period + self.settings.timeout
        for bound, value in items:
            if bound.binding.direction.reads:
                self._expect[bound.name] = (value, until)

    def _expire(self) -> None:
        """Expectations whose echo never came: the last value the remote sent meanwhile is the truth."""
        now = self.clock.now()
        expired = [name for name, (_, until) in self._expect.items() if now > until]
        changed = []
        for name in expired:
            del self._expect[name]
            if name in self._held:
                self.bound[name].value = self._held.pop(name)
                changed.append(self.bound[name])
        if changed:
            self.received(changed)

    def health(self) -> Quality:
        """The quality the link's state allows: GOOD, UNCERTAIN after 2x the period without data, BAD after 5x or down."""
        if not self.connected or self.last_data is None:
            return Quality.BAD
        age = self.clock.now() - self.last_data
        if age > BAD_AFTER * self.quality_period:
            return Quality.BAD
        if age > UNCERTAIN_AFTER * self.quality_period:
            return Quality.UNCERTAIN
        return Quality.GOOD

    @property
    def quality_period(self) -> float:
        """The period the quality rule counts in: the link's, but at least 10 ms (a poll every 1 ms is not judged by 2 ms of silence)."""
        return max(self.settings.period, MIN_QUALITY_PERIOD)

    def _publish_all(self) -> None:
        self.publisher.publish(self.readers, self.health())
        self._update_sys()

    async def _watch(self) -> None:
        """Every half period (at least every 10 ms): age the data, and say so in the tags' quality."""
        tick = self.quality_period / 2
        shown = Quality.GOOD
        while True:
            await self.clock.sleep(tick)
            if self._expect:
                self._expire()
            self._update_sys()  # the round trip, at the watchdog's pace rather than at every poll
            health = self.health()
            if self.connected:
                self._set_state(LinkState.UP if health is Quality.GOOD else LinkState.LATE)
            if health is not shown:
                shown = health
                if self.connected and health is not Quality.GOOD:
                    now = self.clock.now()
                    age = now - (self.last_data or 0.0)
                    self.error = f"no data for {age * 1000:.0f} ms ({age / self.quality_period:.1f}x the period)"
                    quiet = self._late_logged is None or now - self._late_logged >= LATE_LOG_INTERVAL
                    log.log(logging.WARNING if quiet else logging.DEBUG, "link %s: %s: bound tags %s", self.name, self.error, health.value.upper())
                    if quiet:
                        self._late_logged = now
                self._publish_all()

    def _set_state(self, state: LinkState) -> None:
        if state is not self.state:
            self.state = state
            self._update_sys()

    # -- data out -----------------------------------------------------------------------

    def local_changes(self, tags: Sequence[Tag]) -> None:
        """Tags changed locally (a program's output, a client's write): send those bound out, latest value first.

        Only while this plant is active: a standby's image is the active's, mirrored, and the active
        writes it out (docs/redundancy.md)."""
        active = self.plant.role.is_active()
        for tag in tags:
            bound = self.bound.get(tag.name)
            if bound is None or not bound.binding.direction.writes:
                continue
            before = self._local.get(tag.name, _UNSEEN)
            self._local[tag.name] = tag.value
            if not active:
                continue
            if tag.name not in self._pending:
                if tag.value == bound.value:
                    continue  # what the remote holds already (for a `both` tag: its own value, just received; no echo)
                if tag.value == before and type(tag.value) is type(before):
                    # Only the tag's quality changed (the link late for a moment): its value was sent
                    # already, or is on its way, or was refused. Sent again, it could land after the
                    # remote's own change of a `both` tag and overwrite it.
                    continue
            self._pending[tag.name] = tag.value
        self._schedule_flush()

    def _schedule_flush(self) -> None:
        if self._pending and self.connected and (self._flushing is None or self._flushing.done()):
            self._flushing = asyncio.ensure_future(self._flush())

    async def _flush(self) -> None:
        while self._pending and self.connected:
            batch, self._pending = self._pending, {}
            clients = []
            for name in list(batch):
                noted = self.client_writes.pop(name, None)
                if noted is not None and noted[0] == batch[name]:
                    clients.append((name, batch.pop(name), noted[1]))
            if not self.plant.role.is_active():
                return  # fenced since the change (a freeze in the middle of a scan): the new active writes
            items = [(self.bound[name], value) for name, value in batch.items()]
            failed = False
            if items:
                self._expecting(items)
                try:
                    answers = await self.write(items)
                except LinkError as error:
                    self.writes["failed"] += len(items)
                    for name, value in batch.items():
                        self._pending.setdefault(name, value)  # unless a newer value came meanwhile
                    log.debug("link %s: write failed: %s", self.name, error)
                    failed = True
                else:
                    self.took(items, answers)
            for name, value, origin in clients:
                if not await self._send_for(origin, name, value):
                    failed = True
            if failed:
                # Sent again a period later while the link is up (a request that failed alone — an
                # answer later than the timeout from a stalled remote, a service fault — leaves the
                # connection up: no reconnect would ever send it), else after the reconnect.
                await self.clock.sleep(self.settings.period)

    async def _send_for(self, origin: Origin, name: str, value: Any) -> bool:
        """A client's write goes out as the `links.write` command in its name: the remote's answer is audited.

        False when it could not be sent (no answer in time, the link down): the tag holds the value
        here, so it stays pending and goes out again as the runtime's, as after a reconnect."""
        failed = self.writes["failed"]
        try:
            await self.plant.commands.call(WRITE_COMMAND, {"tag": name, "value": value}, origin)
        except CommandRefused as refused:
            log.debug("link %s: %s", self.name, refused)
        if self.writes["failed"] > failed and self.db.value(name) == value:
            self._pending.setdefault(name, value)
            return False
        return True

    async def write_one(self, bound: BoundTag, value: Any) -> str | None:
        """Send one value now; the remote's refusal, or None. Raises LinkError when the link is down."""
        if not self.connected:
            raise LinkError(f"link {self.name} is {self.state.value}: {self.error or 'not connected'}")
        self._expecting([(bound, value)])
        try:
            answers = await self.write([(bound, value)])
        except LinkError:
            self.writes["failed"] += 1
            raise
        self.took([(bound, value)], answers)
        return answers[0]

    def took(self, items: Sequence[tuple[BoundTag, Any]], answers: Sequence[str | None]) -> None:
        """Note the remote's answers to writes: the value it holds now, or why it refused."""
        for (bound, value), refusal in zip(items, answers):
            if refusal is None:
                self.writes["ok"] += 1
                bound.refused = ""
                if not bound.binding.direction.reads:
                    bound.value = value  # what the remote holds now (a `both` tag learns it from the echo)
                continue
            self._expect.pop(bound.name, None)
            if bound.name in self._held:
                bound.value = self._held.pop(bound.name)
            self.writes["refused"] += 1
            bound.refused = f"the remote refused {value!r}: {refusal}"
            self.error = f"{bound.name} = {value!r} refused by the remote: {refusal}"
            log.warning("link %s: %s", self.name, self.error)
        self._update_sys()

    # -- the _sys.links. tags -----------------------------------------------------------

    def _update_sys(self) -> None:
        prefix = f"{PREFIX}{self.name}."
        values = {
            "connected": self.connected,
            "state": self.state.value,
            "error": self.error,
            "bad_tags": sum(1 for bound in self.readers if bound.shown is None or bound.shown[1] is not Quality.GOOD),
            "reconnects": self.reconnects,
            "round_trip_ms": round(self.round_trip * 1000.0, 3),
        }
        changed = [(prefix + key, value) for key, value in values.items() if self._sys.get(key) != value]
        if changed:
            self._sys.update(values)
            self.db.submit(changed, self.origin)

    def describe(self) -> dict[str, Any]:
        """What `links.list` says of this link."""
        age = None if self.last_data is None else round(self.clock.now() - self.last_data, 3)
        return {
            "name": self.name, "protocol": self.settings.protocol, "address": self.settings.address,
            "state": self.state.value, "connected": self.connected, "error": self.error,
            "period_ms": self.settings.period * 1000.0, "tags": len(self.bound), "bad_tags": self._sys.get("bad_tags", 0),
            "reconnects": self.reconnects, "attempts": self.attempts, "requests": self.requests, "writes": dict(self.writes),
            "round_trip_ms": round(self.round_trip * 1000.0, 3), "data_age_s": age, "prefix": f"{PREFIX}{self.name}.",
        }
