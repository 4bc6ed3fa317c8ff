"""The one clock everything that waits takes its time from: real, or simulated.

`RealClock` follows the monotonic system clock. `SimClock` is a discrete-event clock: time
jumps to the next deadline as soon as every coroutine waiting on the clock is idle, so a
20-minute plant run takes seconds and the order of events is the same every run. With
`speed=N` it runs N times faster than real time instead of as fast as possible.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import time
from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Iterator
from typing import Any, TypeVar

from softplc.util.tasks import within

T = TypeVar("T")


class Clock(ABC):
    """Time source for the runtime: `now()` is monotonic seconds since the clock started."""

    @abstractmethod
    def now(self) -> float: ...

    @abstractmethod
    def wall(self) -> float:
        """Seconds since the Unix epoch corresponding to `now()` (for tag timestamps)."""

    @abstractmethod
    async def sleep_until(self, deadline: float) -> None: ...

    async def sleep(self, seconds: float) -> None:
        await self.sleep_until(self.now() + max(0.0, seconds))

    def monotonic(self) -> float:
        """System-wide monotonic seconds now, comparable across processes (simulated: `now()`)."""
        return self.now()

    @abstractmethod
    async def run_blocking(self, function: Callable[..., T], *args: Any) -> T:
        """Run blocking work (e.g. path planning) without stalling the clock's consumers."""

    async def sleep_until_release(self, release: float) -> None:
        """Sleep until a scan task's release (the scan engine's own sleep; see RealClock)."""
        await self.sleep_until(release)

    def cycle_done(self) -> None:
        """The scan cycle the engine slept for has run (or the engine stopped)."""

    @property
    def simulated(self) -> bool:
        return False


_SPIN_MARGIN = 0.0005
# Longest nap of the last stretch before a deadline (blocks the loop that long: a request that
# arrives meanwhile waits for its end). 0.1 ms, not 0.2: at a 1 ms scan the OPC UA handshake took
# 2.45-2.53 ms instead of 2.72-3.11, a 1 ms task overran 10-11 times in 15 s instead of 24-32, for
# 2 % of a core more (docs/benchmarks.md, "The OPC UA handshake against its floor").
_NAP = 0.0001


class RealClock(Clock):
    """Monotonic real time.

    The scan engine's sleep (`sleep_until_release`) is precise: `spin` is how long before a
    release it stops sleeping in the event loop and spins (yielding to the loop) instead:
    event-loop timers fire late (asyncio's ~1-2 ms on a typical Linux VM: epoll's millisecond
    resolution and more; uvloop's ~0.3 ms early), which would dominate a 10 ms task's start
    latency. The margin adapts: it follows the recent worst lateness of the loop's timers plus
    0.5 ms, between 0.5 ms and `max_spin`.

    Every other sleeper (`sleep`, `sleep_until`: robots' control cycles, link polls, heartbeats)
    wakes on the loop's timer, up to a couple of milliseconds after its deadline and never before
    it, without spinning: the spin before each robot group's wake-up (ten a cycle) and each other
    timer cost the default plant a fifth of its CPU (10 robots: 17 % of a core → 6 %;
    docs/benchmarks.md), for a precision nothing but a scan release needs.

    Scan cycles come first: any other sleeper that wakes less than `guard` (5 ms) before the scan
    engine's next release (or after it, while that cycle has not run yet) waits until the cycle
    is done, and then runs in the gap before the following release. Without this, a robot's
    control step or the housekeeping due at the same moment as a 10 ms task would delay it.
    """

    def __init__(self, spin: float = 0.0015, guard: float = 0.005, *, max_spin: float = 0.004) -> None:
        self._origin = time.monotonic()
        self._wall_origin = time.time()
        self.spin = spin
        self.max_spin = max_spin
        self._lateness = spin - _SPIN_MARGIN  # decaying maximum of how late timers fired
        self.guard = guard
        self._release: float | None = None  # the scan engine's next release, while it waits
        self._cycle_event: asyncio.Event | None = None

    def now(self) -> float:
        return time.monotonic() - self._origin

    def wall(self) -> float:
        return self._wall_origin + self.now()

    def monotonic(self) -> float:
        # time.monotonic() is one clock for every process on the machine (CLOCK_MONOTONIC on
        # Linux), so another process can subtract its own readings from it.
        return time.monotonic()

    async def sleep_until(self, deadline: float) -> None:
        remaining = deadline - self.now()
        await asyncio.sleep(max(remaining, 0.0))  # a zero sleep still gives the loop a turn
        while self.now() < deadline:  # a timer may fire a clock tick early
            await asyncio.sleep(0)
        release = self._release
        if release is not None and self.now() >= release - self.guard:
            await self._cycle_done().wait()  # a scan cycle is about to start: let it go first

    async def sleep_until_release(self, release: float) -> None:
        self._release = release
        self._cycle_done().clear()
        await self._sleep_until(release)

    def cycle_done(self) -> None:
        self._release = None
        if self._cycle_event is not None:
            self._cycle_event.set()

    def _cycle_done(self) -> asyncio.Event:
        if self._cycle_event is None:
            self._cycle_event = asyncio.Event()
        return self._cycle_event

    async def _sleep_until(self, deadline: float) -> None:
        remaining = deadline - self.now()
        # A wait shorter than the margin (a 1 ms task) would be spun entirely, i.e. the CPU
        # never rests; such waits nap in the kernel between loop turns instead. Longer waits
        # spin only the last stretch, with loop turns in between: in a virtual machine a
        # waking vCPU may take milliseconds, so a short spin is what makes a 10 ms task precise.
        napping = remaining <= self.spin
        if remaining > self.spin:
            target = deadline - self.spin
            await asyncio.sleep(remaining - self.spin)
            # Learn how late the loop's timers fire; forget a spike slowly (2 % per wake-up).
            self._lateness = max(self.now() - target, self._lateness * 0.98)
            self.spin = min(max(self._lateness + _SPIN_MARGIN, _SPIN_MARGIN), self.max_spin)
        elif remaining <= 0:
            await asyncio.sleep(0)  # always give the loop a turn, as SimClock and asyncio.sleep(0) do
        while self.now() < deadline:
            await asyncio.sleep(0)
            remaining = deadline - self.now()
            if napping and remaining > 0 and not _has_ready_callbacks():
                # Spinning all the time would also use up a real-time process's budget
                # (--rt-priority), and Linux then throttles it for 50 ms every second.
                # Only an idle loop naps: a nap between the steps of a request's callback chain
                # (data received → task → reply) made every server reply 1 ms slower at a 1 ms scan.
                time.sleep(min(remaining, _NAP))

    async def run_blocking(self, function: Callable[..., T], *args: Any) -> T:
        return await asyncio.get_running_loop().run_in_executor(None, function, *args)


class SimClock(Clock):
    """Simulated time that advances from deadline to deadline.

    Call `await clock.drive()` (the runtime does) to advance time: whenever the event loop
    has nothing ready to run, the earliest waiting sleeper is woken with `now()` set to its
    deadline. Ties wake in the order the sleeps were requested, so runs are reproducible.
    """

    def __init__(self, speed: float | None = None, epoch: float = 1_767_225_600.0) -> None:
        if speed is not None and speed <= 0:
            raise ValueError("speed must be positive")
        self.speed = speed
        self._now = 0.0
        self._epoch = epoch  # 2026-01-01T00:00:00Z: fixed so simulated timestamps repeat
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._sequence = itertools.count()
        self._wakeup: asyncio.Event | None = None

    @property
    def simulated(self) -> bool:
        return True

    def now(self) -> float:
        return self._now

    def wall(self) -> float:
        return self._epoch + self._now

    async def sleep_until(self, deadline: float) -> None:
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (max(deadline, self._now), next(self._sequence), future))
        if self._wakeup is not None:
            self._wakeup.set()
        await future

    async def run_blocking(self, function: Callable[..., T], *args: Any) -> T:
        # Simulated time stands still while the work runs, so running it inline is both
        # faithful and deterministic.
        return function(*args)

    async def drive(self, until: float | None = None) -> None:
        """Advance time forever (or until `until`), waking sleepers in deadline order."""
        loop = asyncio.get_running_loop()
        self._wakeup = asyncio.Event()
        with _sparse_polling(loop, self.speed is None):
            await self._drive(loop, until)

    async def _drive(self, loop: asyncio.AbstractEventLoop, until: float | None) -> None:
        real_origin = time.monotonic()
        sim_origin = self._now
        assert self._wakeup is not None
        while until is None or self._now < until:
            await _settle(loop)
            while self._sleepers and self._sleepers[0][2].cancelled():
                heapq.heappop(self._sleepers)
            if not self._sleepers:
                self._wakeup.clear()
                await self._wakeup.wait()
                continue
            deadline = self._sleepers[0][0]
            if until is not None and deadline > until:
                self._now = until
                break
            if self.speed is not None:
                real_deadline = real_origin + (deadline - sim_origin) / self.speed
                delay = real_deadline - time.monotonic()
                if delay > 0:
                    self._wakeup.clear()
                    try:
                        # A new, earlier sleeper may arrive while we wait in real time.
                        await within(delay, self._wakeup.wait())
                        continue
                    except TimeoutError:
                        pass
            _, _, future = heapq.heappop(self._sleepers)
            self._now = deadline
            if not future.done():
                future.set_result(None)


class PlantTime(Clock):
    """The clock programs see: the runtime's clock shifted by an offset (0 unless a redundant pair aligned it).

    Programs keep times in their state (a timer's start, a last-seen moment) on this clock. The
    two runtimes of a redundant pair have clocks that started at different moments; a standby
    shifts its programs' time onto the active's (`align`), so when it takes over with the
    active's program state, a timer started there goes on exactly where it was.
    """

    def __init__(self, base: Clock) -> None:
        self.base = base
        self.offset = 0.0

    def align(self, now: float) -> None:
        """Make `now()` read `now` at this instant (the active's program time, just received)."""
        self.offset = now - self.base.now()

    def now(self) -> float:
        return self.base.now() + self.offset

    def wall(self) -> float:
        return self.base.wall()

    def monotonic(self) -> float:
        return self.base.monotonic()

    async def sleep_until(self, deadline: float) -> None:
        await self.base.sleep_until(deadline - self.offset)

    async def run_blocking(self, function: Callable[..., T], *args: Any) -> T:
        return await self.base.run_blocking(function, *args)

    @property
    def simulated(self) -> bool:
        return self.base.simulated


@contextlib.contextmanager
def _sparse_polling(loop: asyncio.AbstractEventLoop, sparse: bool) -> Iterator[None]:
    """While time runs as fast as possible, ask the kernel for I/O every 8th loop turn, not every one.

    The loop is then never idle (the next sleeper is always ready), so each of its turns asks
    the kernel for I/O without waiting (epoll_wait with a timeout of 0): ~35,000 system calls,
    a tenth of a simulated ten minutes of the default plant. A client's request is then seen a
    few turns later — microseconds; a turn that may wait (nothing ready) always asks.
    """
    selector = getattr(loop, "_selector", None)  # asyncio's selector loops; uvloop has none
    if not sparse or selector is None or "select" in vars(selector):
        yield
        return
    select = selector.select
    turns = itertools.count()

    def sparse_select(timeout: float | None = None) -> list[Any]:
        if timeout == 0 and next(turns) % 8:
            return []
        return select(timeout)

    selector.select = sparse_select
    try:
        yield
    finally:
        del selector.select


def _has_ready_callbacks() -> bool:
    """Whether the running asyncio loop has callbacks queued for its next turn (False if it cannot tell)."""
    ready = getattr(asyncio.get_running_loop(), "_ready", None)  # asyncio's run queue; uvloop has none
    return bool(ready)


async def _settle(loop: asyncio.AbstractEventLoop) -> None:
    """Yield until the event loop has no ready callbacks left (everyone is waiting)."""
    ready = getattr(loop, "_ready", None)
    if ready is None:  # an event loop without a visible ready queue: yield generously
        for _ in range(20):
            await asyncio.sleep(0)
        return
    await asyncio.sleep(0)
    for _ in range(10_000):
        if not ready:
            return
        await asyncio.sleep(0)


async def wait_for(clock: Clock, awaitable: Awaitable[T], timeout: float) -> T:
    """`asyncio.wait_for` with the timeout measured on `clock`."""
    task = asyncio.ensure_future(awaitable)
    timer = asyncio.ensure_future(clock.sleep(timeout))
    try:
        done, _ = await asyncio.wait({task, timer}, return_when=asyncio.FIRST_COMPLETED)
        if task in done:
            return task.result()
        task.cancel()
        raise TimeoutError(f"timed out after {timeout} s")
    finally:
        timer.cancel()
        if not task.done():
            task.cancel()  # we were cancelled ourselves: what we waited for goes too
