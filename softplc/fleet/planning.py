"""Where robots' A* plans run: inline on the simulated clock, in a worker process in real time.

A plan is pure Python and takes up to ~45 ms on the factory map. Run in a thread it holds the
interpreter's lock (the GIL) all that time, and each time the event loop wants the lock back it
waits up to the switch interval (5 ms): a 10 ms scan task then started 5-12 ms late whenever a
robot planned (`bench/scan_jitter.py`). A worker process has an interpreter of its own, so the
scan never waits for a plan. The planners (the inflated maps) are sent to the worker once, as
its first task; each request carries only its start, goal and temporary obstacles.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import signal
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Protocol

from softplc.clock import Clock
from softplc.fleet.driver import PlanRequest, run_plan
from softplc.fleet.planner import Corridor, Disc, PathPlanner, Plan

log = logging.getLogger(__name__)


class Planning(Protocol):
    """Runs plan requests without stalling the event loop."""

    async def run(self, request: PlanRequest) -> Plan: ...


@dataclass
class ClockPlanning:
    """Plans through `clock.run_blocking`: inline on the simulated clock (deterministic), a thread in real time."""

    clock: Clock

    async def run(self, request: PlanRequest) -> Plan:
        return await self.clock.run_blocking(run_plan, request)


# A request as it crosses to the worker: the planner is named by its index in the worker's list.
_Transit = tuple[int, int, tuple[float, float], tuple[float, float], list[Disc], list[Corridor], bool, bool]

_worker_planners: list[PathPlanner] = []


def _start_worker() -> None:
    """Worker initialiser: leave Ctrl-C to the runtime; normal scheduling."""
    # The worker was started with SIGINT blocked (see _sigint_blocked): ignore it for good
    # before unblocking, so a Ctrl-C at the terminal (sent to the whole process group) is the
    # runtime's to handle, and never kills the worker half-way.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    # Under `softplc run --rt-priority` the worker would inherit SCHED_FIFO and could starve
    # the scan on a small machine: planning is background work.
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _install(planners: list[PathPlanner]) -> int:
    global _worker_planners
    _worker_planners = planners
    return os.getpid()


def _plan_in_worker(transit: _Transit) -> Plan:
    index, serial, start, goal, discs, keep_out, detour, make_way = transit
    return run_plan(PlanRequest(serial, _worker_planners[index], start, goal, discs, keep_out, detour, make_way))


@contextmanager
def _sigint_blocked() -> Iterator[None]:
    """Block SIGINT in this thread meanwhile; a process started meanwhile inherits the block."""
    if not hasattr(signal, "pthread_sigmask"):  # not POSIX: nothing to block
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class ProcessPlanning:
    """Plans in a worker process that holds a copy of every planner (see the module docstring).

    A request for a planner the worker was not given (a robot size unknown at start) runs
    through `fallback` instead.
    """

    def __init__(self, planners: Sequence[PathPlanner], fallback: Planning) -> None:
        self._planners = list(planners)
        self._index = {id(planner): index for index, planner in enumerate(self._planners)}
        self._fallback = fallback
        self._pool: ProcessPoolExecutor | None = None
        self._restarting = asyncio.Lock()
        self.worker_pid: int | None = None

    async def start(self) -> None:
        """Start the worker and wait until it holds the planners (about half a second)."""
        # spawn, not fork: forking a process that runs an event loop and threads is unsafe.
        # One worker: the planners are its first task, and it plans one request at a time.
        self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=_start_worker)
        loop = asyncio.get_running_loop()
        # The worker process is started by this first submit. The planners go through the
        # pool's queue, written by its feeder thread: a payload bigger than a pipe's buffer
        # never blocks the event loop, even if the worker died meanwhile.
        with _sigint_blocked():
            installed = loop.run_in_executor(self._pool, _install, self._planners)
        self.worker_pid = await installed

    async def run(self, request: PlanRequest) -> Plan:
        index = self._index.get(id(request.planner))
        pool = self._pool
        if pool is None or index is None:
            return await self._fallback.run(request)
        transit: _Transit = (index, request.serial, request.start, request.goal, request.discs,
                             request.keep_out, request.detour, request.make_way)
        loop = asyncio.get_running_loop()
        try:
            return await loop.run_in_executor(pool, _plan_in_worker, transit)
        except BrokenProcessPool:
            # The worker died (killed, out of memory): start a new one and plan there.
            if not await self._restart(pool):
                return await self._fallback.run(request)
            assert self._pool is not None
            return await loop.run_in_executor(self._pool, _plan_in_worker, transit)

    async def _restart(self, broken: ProcessPoolExecutor) -> bool:
        """Replace a broken pool (once, however many requests found it broken); False if that failed."""
        async with self._restarting:
            if self._pool is broken:
                log.warning("the planning worker process (pid %s) died; starting a new one", self.worker_pid)
                broken.shutdown(wait=False, cancel_futures=True)
                self._pool = None
                try:
                    await self.start()
                except Exception:  # planning still works in the fallback (a thread)
                    log.exception("cannot start a planning worker process; planning in a thread instead")
                    self._pool = None
            return self._pool is not None

    def stop(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
