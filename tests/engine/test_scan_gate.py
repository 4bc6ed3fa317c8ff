"""The scan gate: a worker thread steps aside around the scan's releases, and never waits for a cycle that does not come."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from pathlib import Path

from softplc.app.runtime import Runtime
from softplc.config.plant import PlantConfig
from softplc.core.clock import RealClock

PLANT = """
tags:
  counter: {type: int32}
tasks:
  fast: {interval: 10ms}
"""


def calls(count: int) -> int:
    """Python work of `count` calls (each a call and a return the gate looks at)."""
    total = 0
    for number in range(count):
        total += abs(number)
    return total


def in_worker(runtime: Runtime, work: Callable[[], object]) -> float:
    """Run `work` in a thread inside the runtime's gate; the seconds it took (fails after 60 s)."""
    took: list[float] = []

    def run() -> None:
        started = time.monotonic()
        with runtime.scan_gate.worker():
            work()
        took.append(time.monotonic() - started)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(60)
    assert took, "the worker was still waiting for the scan after 60 s"
    return took[0]


async def test_a_worker_steps_aside_while_the_scan_runs(make_config: Callable[[str], PlantConfig], tmp_path: Path) -> None:
    runtime = Runtime(make_config(PLANT), RealClock(), state_dir=tmp_path / "state")
    await runtime.start()
    try:
        gate = runtime.scan_gate
        took = await asyncio.to_thread(in_worker, runtime, lambda: calls(400_000))
        assert gate.pauses > 0  # it did meet releases, and waited for their cycles
        assert took < 30
    finally:
        await runtime.stop()


async def test_a_worker_does_not_wait_at_every_call_for_a_scan_that_has_stopped(make_config: Callable[[str], PlantConfig], tmp_path: Path) -> None:
    # An online change's check still importing when the runtime stops (a test's end, a Ctrl-C):
    # the next release never comes. Waiting 50 ms for it at each of the import's calls took a
    # suite run's worker for ever (its event loop, closing, waited for the thread).
    runtime = Runtime(make_config(PLANT), RealClock(), state_dir=tmp_path / "state")
    await runtime.start()
    gate = runtime.scan_gate
    await runtime.stop()
    took = in_worker(runtime, lambda: calls(200))  # 400 calls and returns: 20 s at 50 ms each
    assert took < 5, f"{took:.1f} s for 200 calls after the scan stopped ({gate.pauses} pauses)"
    assert gate.pauses <= 5
