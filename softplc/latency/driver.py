"""What a handshake client needs from a protocol: read the handshake tags, answer, wait for Ready.

A driver reads every handshake tag at once into a `Snapshot` and answers a Ready by writing
the next TaskID and clearing Ready. How it learns that Ready was set is the protocol's
business: by polling (`PollingDriver`) or by an OPC UA subscription.
"""

from __future__ import annotations

import asyncio
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace

# The handshake's tags, by role. Only ready and task_id are required of a third-party PLC.
ROLES: tuple[str, ...] = ("ready", "task_id", "delay", "delay_scans", "handshakes", "ready_stamp")
REQUIRED_ROLES: tuple[str, ...] = ("ready", "task_id")

# softplc's handshake plant (programs/handshake.yaml) names them so.
TAG_NAMES: dict[str, str] = {
    "ready": "Ready",
    "task_id": "TaskID",
    "delay": "Delay",
    "delay_scans": "DelayScans",
    "handshakes": "Handshakes",
    "ready_stamp": "ReadyStamp",
}


class DriverError(RuntimeError):
    """The server refused a read or write, or the connection failed; the message says which."""


@dataclass(frozen=True)
class Snapshot:
    """The handshake tags as read at one instant; None for a tag the PLC does not expose."""

    ready: bool
    task_id: int | None = None
    delay: float | None = None
    delay_scans: int | None = None
    handshakes: int | None = None
    ready_stamp: float | None = None
    received: float = 0.0  # client's time.monotonic() when this was read or pushed

    def at(self, received: float) -> Snapshot:
        return replace(self, received=received)


class ReadyTracker:
    """Tells a new Ready from one already answered: by ReadyStamp if served, else by its edge."""

    def __init__(self) -> None:
        self.answered_stamp: float | None = None
        self.answered_once = False
        self.seen_low = True

    def observe(self, snapshot: Snapshot) -> bool:
        """True when `snapshot` shows a Ready that has not been answered yet."""
        if not snapshot.ready:
            self.seen_low = True
            return False
        if snapshot.ready_stamp is not None:
            return not self.answered_once or snapshot.ready_stamp != self.answered_stamp
        return self.seen_low

    def answered(self, snapshot: Snapshot) -> None:
        self.answered_stamp = snapshot.ready_stamp
        self.answered_once = True
        self.seen_low = False


class Driver(ABC):
    """A connection to the PLC speaking one protocol."""

    description = ""

    @abstractmethod
    async def connect(self) -> None: ...

    @abstractmethod
    async def close(self) -> None: ...

    @abstractmethod
    async def read(self) -> Snapshot:
        """All handshake tags in one request where the protocol allows it."""

    @abstractmethod
    async def answer(self, task_id: int) -> tuple[float, float] | None:
        """Write TaskID and clear Ready (one request where the protocol allows it).

        None: the write was made in this call (the caller times it); (sent, done), monotonic s: it
        was made ahead, where the driver saw Ready (see `prepare`)."""

    def prepare(self, task_id: int) -> None:
        """The TaskID the next new Ready will be answered with: a driver that sees Ready where it
        arrives may send the answer at once, and `answer` then returns its times."""

    @abstractmethod
    async def wait_ready(self, tracker: ReadyTracker, timeout: float) -> Snapshot:
        """The first snapshot with a new Ready; raises TimeoutError after `timeout` seconds."""

    @abstractmethod
    async def settle(self, ready: Snapshot, handshakes: int | None, timeout: float) -> Snapshot:
        """After an answer: a snapshot read once the PLC took it (Ready low, or Handshakes no longer
        `handshakes`), or the latest one after `timeout`. Not timed: it carries the PLC's figures."""

    def rearm(self) -> None:
        """Treat the Ready showing now as new again (to answer a Ready the PLC did not take)."""

    @property
    def serves(self) -> set[str]:
        """The roles this PLC exposes."""
        return set(ROLES)


class PollingDriver(Driver):
    """Waits by reading all handshake tags every `poll_interval` seconds, like the thesis's client."""

    poll_interval = 0.001

    async def wait_ready(self, tracker: ReadyTracker, timeout: float) -> Snapshot:
        deadline = time.monotonic() + timeout
        # Polls start every poll_interval (a read that takes longer is followed at once, never by
        # a burst): sleeping a whole interval after each read made the period interval + round
        # trip, and a Ready waited that much longer to be seen.
        due = time.monotonic()
        while True:
            snapshot = await self.read()
            if tracker.observe(snapshot):
                return snapshot
            if snapshot.received >= deadline:
                raise TimeoutError(f"no new Ready within {timeout:g} s")
            due = max(due + self.poll_interval, time.monotonic())
            await asyncio.sleep(due - time.monotonic())

    async def settle(self, ready: Snapshot, handshakes: int | None, timeout: float) -> Snapshot:
        deadline = time.monotonic() + timeout
        while True:
            snapshot = await self.read()
            taken = snapshot.handshakes != handshakes if handshakes is not None else not snapshot.ready
            if taken:
                return snapshot
            if snapshot.received >= deadline:
                return snapshot
            await asyncio.sleep(self.poll_interval)
