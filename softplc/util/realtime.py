"""Real-time scheduling for `softplc run --rt-priority N`: scans are not delayed by other processes.

On a busy machine the operating system hands the CPU to other processes for milliseconds at a
time, which shows up directly as start latency of fast tasks. Like other soft PLCs on Linux,
softplc can run its event loop under the SCHED_FIFO policy, which preempts every ordinary
process. Blocking work sent to the executor (e.g. path planning) stays at normal priority, and
the interpreter's thread switch interval is shortened so such a thread holding the GIL cannot
hold the event loop back for the default 5 ms.
"""

from __future__ import annotations

import asyncio
import os
import sys
from concurrent.futures import ThreadPoolExecutor

SWITCH_INTERVAL = 0.0005  # seconds a thread may hold the GIL while the loop thread waits for it


def shorten_switch_interval() -> None:
    """Let a thread that runs Python code (a store's writer) hold the GIL at most SWITCH_INTERVAL."""
    # With the interpreter's default 5 ms it could keep the event loop waiting for the GIL that
    # long between its SQL calls, i.e. a late 10 ms scan. Never lengthened: --rt-priority sets the same.
    if sys.getswitchinterval() > SWITCH_INTERVAL:
        sys.setswitchinterval(SWITCH_INTERVAL)


class RealtimeError(RuntimeError):
    """Real-time scheduling could not be set up; the message says why and what to do."""


def set_realtime_priority(priority: int) -> None:
    """Run the calling thread (the event loop's) under SCHED_FIFO at `priority`."""
    if not hasattr(os, "sched_setscheduler"):
        raise RealtimeError("real-time scheduling (SCHED_FIFO) is not available on this system")
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not low <= priority <= high:
        raise RealtimeError(f"the real-time priority must be between {low} and {high}, not {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        raise RealtimeError(
            "not permitted to use real-time scheduling: run as root, give the Python binary "
            "CAP_SYS_NICE (setcap cap_sys_nice+ep), or raise 'rtprio' in /etc/security/limits.conf"
        ) from None
    sys.setswitchinterval(SWITCH_INTERVAL)


def _normal_priority() -> None:
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def use_normal_priority_executor(loop: asyncio.AbstractEventLoop) -> None:
    """Run the loop's blocking work in threads at normal priority (they would inherit SCHED_FIFO)."""
    loop.set_default_executor(ThreadPoolExecutor(thread_name_prefix="softplc-blocking", initializer=_normal_priority))
