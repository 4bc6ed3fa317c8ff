"""Online change on the real clock: a 10 ms task keeps every cycle while its program is swapped.

The check (YAML, schema, fresh imports, the new version's setup()) runs in a worker thread while
the task scans; the swap is a pointer change between two cycles. Timing figures (start latency
during the swap) are measured by bench/online_change.py, not asserted here.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path

from softplc.clock import RealClock

from test_online_change import Plant


async def wait_until(condition: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll `condition` every 10 ms (yielding to the runtime) until it holds or `timeout` passes."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(0.01)


async def test_a_10ms_task_misses_no_cycle_while_its_program_is_changed_online(tmp_path: Path) -> None:
    """Three changes in a row; on a machine shared with other work a cycle may be missed for reasons
    of its own, so the test asks that at least one change went by without any missed cycle (a change
    that costs cycles costs them every time) — and that no change ever loses or repeats a scan."""
    plant = Plant(tmp_path, RealClock())
    runtime = plant.runtime
    fast = runtime.tasks[0]
    await runtime.start()
    try:
        await wait_until(lambda: fast.stats.cycles >= 50, 10, "50 cycles of the 10 ms task")
        missed = []
        for version in (2, 3, 4):
            old = runtime.program("mix")
            overruns = fast.stats.overruns
            plant.edit(f"self.version = {version - 1}", f"self.version = {version}")
            result = await plant.apply()
            assert result["applied"] is True
            swapped_at = fast.stats.cycles
            await wait_until(lambda: fast.stats.cycles >= swapped_at + 2, 10, "two more cycles")
            missed.append(fast.stats.overruns - overruns)
            mix = runtime.program("mix")
            assert mix is not old and mix.version == version and plant.value("version") == version
            # every cycle scanned the program exactly once: its carried-over count is the task's cycle count
            assert mix.program.count == fast.stats.cycles == plant.value("scans")
        assert 0 in missed, f"cycles missed while each change was checked and swapped: {missed}"
    finally:
        await runtime.stop()
