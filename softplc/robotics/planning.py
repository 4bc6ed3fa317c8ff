"""Where robots' A* plans run: inline on the simulated clock, in a worker process in real time.

A plan is pure Python and takes up to ~45 ms on the factory map. Run in a thread it holds the
interpreter's lock (the GIL) all that time, and each time the event loop wants the lock back it
waits up to the switch interval (5 ms): a 10 ms scan task then started 5-12 ms late whenever a
robot planned (`bench/scan_jitter.py`). A worker process has an interpreter of its own, so the
scan never waits for a plan. The planners (the inflated maps) are sent to the worker once, as
its first request; each plan request carries only its start, goal and temporary obstacles.

The worker is a plain subprocess (`python -m softplc.robotics.planning_worker`) speaking framed
pickles over its stdin and stdout, not a multiprocessing pool: that would re-import the
program that embeds softplc (its `__main__`) in the worker, and fail for a script without an
`if __name__ == "__main__":` guard.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import os
import pickle
import signal
import struct
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from softplc.core.clock import Clock
from softplc.robotics.driver import PlanRequest, run_plan
from softplc.robotics.planner import PathPlanner, Plan
from softplc.util.tasks import within

log = logging.getLogger(__name__)

HEADER = struct.Struct(">I")  # a frame: its length, then a pickle


def frame(value: Any) -> bytes:
    payload = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    return HEADER.pack(len(payload)) + payload


class Planning(Protocol):
    """Runs plan requests without stalling the event loop."""

    async def run(self, request: PlanRequest) -> Plan: ...


@dataclass
class ClockPlanning:
    """Plans through `clock.run_blocking`: inline on the simulated clock (deterministic), a thread in real time."""

    clock: Clock

    async def run(self, request: PlanRequest) -> Plan:
        return await self.clock.run_blocking(run_plan, request)


class WorkerGone(RuntimeError):
    """The planning worker process ended (killed, crashed) before it answered."""


@contextmanager
def _sigint_blocked() -> Iterator[None]:
    """Block SIGINT in this thread meanwhile; a process started meanwhile inherits the block.

    The worker ignores SIGINT as its first statement; until then a Ctrl-C at the terminal
    (sent to the whole process group) would kill it half-way through its start.
    """
    if not hasattr(signal, "pthread_sigmask"):  # not POSIX: nothing to block
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class _Worker:
    """One worker process and the requests waiting for its answers."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self.process = process
        self.pid = process.pid
        self._waiting: dict[int, asyncio.Future[Any]] = {}
        self._idents = itertools.count()
        self._reader = asyncio.create_task(self._read_answers(), name=f"planning-worker-{process.pid}")

    @classmethod
    async def start(cls) -> _Worker:
        package_root = str(Path(__file__).resolve().parents[2])  # so the worker imports this softplc
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
        with _sigint_blocked():
            process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "softplc.robotics.planning_worker",
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE, env=env,
            )
        return cls(process)

    @property
    def alive(self) -> bool:
        return not self._reader.done()

    async def call(self, kind: str, body: Any) -> Any:
        ident = next(self._idents)
        answer: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._waiting[ident] = answer
        stdin = self.process.stdin
        assert stdin is not None
        try:
            stdin.write(frame((kind, ident, body)))  # buffered by the transport: never blocks the loop
            await stdin.drain()
        except (ConnectionError, RuntimeError) as error:
            self._waiting.pop(ident, None)
            raise WorkerGone(f"the planning worker (pid {self.pid}) is gone: {error}") from None
        return await answer

    async def _read_answers(self) -> None:
        stdout = self.process.stdout
        assert stdout is not None
        try:
            while True:
                header = await stdout.readexactly(HEADER.size)
                (size,) = HEADER.unpack(header)
                ident, ok, value = pickle.loads(await stdout.readexactly(size))
                answer = self._waiting.pop(ident, None)
                if answer is not None and not answer.done():
                    answer.set_result(value) if ok else answer.set_exception(RuntimeError(value))
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        finally:
            for answer in self._waiting.values():
                if not answer.done():
                    answer.set_exception(WorkerGone(f"the planning worker (pid {self.pid}) ended"))
            self._waiting.clear()

    async def stop(self) -> None:
        if self.process.stdin is not None:
            self.process.stdin.close()  # the worker ends at the end of its input
        try:
            await within(2.0, self.process.wait())
        except TimeoutError:
            self.process.kill()
            await self.process.wait()
        self._reader.cancel()


class ProcessPlanning:
    """Plans in a worker process that holds a copy of every planner (see the module docstring).

    A request for a planner the worker was not given (a robot size unknown at start) runs
    through `fallback`; so does every request if no worker process can be started.
    """

    def __init__(self, planners: Sequence[PathPlanner], fallback: Planning) -> None:
        self._planners = list(planners)
        self._index = {id(planner): index for index, planner in enumerate(self._planners)}
        self._fallback = fallback
        self._worker: _Worker | None = None
        self._restarting = asyncio.Lock()

    @property
    def worker_pid(self) -> int | None:
        return self._worker.pid if self._worker is not None else None

    async def start(self) -> None:
        """Start the worker and wait until it holds the planners (about half a second)."""
        try:
            worker = await _Worker.start()
            await worker.call("planners", self._planners)
        except (OSError, WorkerGone, RuntimeError) as error:
            log.warning("cannot start the planning worker process (%s): robots plan in a thread instead", error)
            return
        self._worker = worker

    async def run(self, request: PlanRequest) -> Plan:
        index = self._index.get(id(request.planner))
        worker = self._worker
        if worker is None or index is None:
            return await self._fallback.run(request)
        transit = (index, request.serial, request.start, request.goal, request.discs,
                   request.keep_out, request.detour, request.make_way)
        try:
            plan: Plan = await worker.call("plan", transit)
            return plan
        except WorkerGone:
            # The worker died (killed, out of memory): start a new one and plan there.
            await self._restart(worker)
            if self._worker is None:
                return await self._fallback.run(request)
            plan = await self._worker.call("plan", transit)
            return plan

    async def _restart(self, dead: _Worker) -> None:
        """Replace a dead worker (once, however many requests found it dead)."""
        async with self._restarting:
            if self._worker is dead:
                log.warning("the planning worker process (pid %s) ended; starting a new one", dead.pid)
                self._worker = None
                await dead.stop()
                await self.start()

    async def stop(self) -> None:
        worker, self._worker = self._worker, None
        if worker is not None:
            await worker.stop()
