"""The HMI's waits rest the CPU: a rate limit's gap between frames is a loop timer, never a spin (pacing.py)."""

from __future__ import annotations

import time

from softplc.adapters.hmi.pacing import Pacer
from softplc.core.clock import RealClock


async def test_the_pacers_waits_leave_the_cpu_idle() -> None:
    # The clock's precise sleep spins the last 0.5-4 ms before its deadline: right for a scan
    # release, ~4 % of a core for the HMI's waits of a few ms between frames (bench/hmi_live.py).
    pacer = Pacer(RealClock(), lambda: 1.0)  # the plant's next release is far off: nothing to let go first
    cpu, wall = time.thread_time(), time.monotonic()
    for _ in range(40):
        await pacer.sleep(0.002)
    cpu, wall = time.thread_time() - cpu, time.monotonic() - wall
    assert wall >= 40 * 0.002
    assert cpu < 0.25 * wall, f"40 waits of 2 ms used {cpu * 1000:.1f} ms of CPU in {wall * 1000:.1f} ms: they spun"
