"""Real-time scheduling for `softplc run --rt-priority N` and `--cpus LIST`: scans are not delayed by other processes.

On a busy machine the operating system hands the CPU to other processes for milliseconds at a
time, which shows up directly as start latency of fast tasks. Like other soft PLCs on Linux,
softplc can run its event loop under the SCHED_FIFO policy, which preempts every ordinary
process. Blocking work sent to the executor (e.g. path planning) stays at normal priority, and
the interpreter's thread switch interval is shortened so such a thread holding the GIL cannot
hold the event loop back for the default 5 ms.

`--cpus` keeps a process on the CPUs given (Linux's affinity, the list syntax of `taskset -c`:
"1", "0,2", "2-3"), as soft PLCs reserve cores for their runtime. A runtime and the client that
answers it on CPUs of their own wake each other without waiting for the other to leave its CPU,
and each finds more of its code still in that CPU's caches: `softplc latency` at a 1 ms scan on a
2-CPU machine answered in 2.2 ms instead of 3.2 ms (docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
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


def parse_cpus(text: str) -> frozenset[int]:
    """CPU numbers from a list like "0", "0,2" or "1-3" (taskset's syntax); ValueError says what is wrong."""
    cpus: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        first, dash, last = part.partition("-")
        if not first.strip().isdigit() or (dash and not last.strip().isdigit()):
            raise ValueError(f"{text!r} is not a CPU list: write CPU numbers and ranges, e.g. 0 or 0,2 or 1-3")
        low, high = int(first), int(last) if dash else int(first)
        if high < low:
            raise ValueError(f"{part!r}: a range goes from the lower CPU number to the higher one")
        cpus.update(range(low, high + 1))
    return frozenset(cpus)


def cpu_list(text: str) -> frozenset[int]:
    """parse_cpus as an argparse type: its message is the one the user sees."""
    try:
        return parse_cpus(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def set_cpu_affinity(cpus: frozenset[int]) -> None:
    """Keep the calling process (its threads to come, too) on `cpus`."""
    if not hasattr(os, "sched_setaffinity"):
        raise RealtimeError("CPU affinity is not available on this system")
    check_cpus(cpus)
    try:
        os.sched_setaffinity(0, cpus)
    except OSError as error:  # e.g. a CPU outside the container's cpuset
        raise RealtimeError(f"cannot keep this process on CPU {format_cpus(cpus)}: {error.strerror}") from None


def check_cpus(cpus: frozenset[int]) -> None:
    """Refuse CPUs this machine does not have (RealtimeError)."""
    count = os.cpu_count() or 1
    outside = sorted(cpu for cpu in cpus if cpu >= count)
    if outside:
        raise RealtimeError(f"there is no CPU {', '.join(map(str, outside))}: this machine has CPU {format_cpus(frozenset(range(count)))}")


def format_cpus(cpus: frozenset[int] | set[int]) -> str:
    """A CPU set in the list syntax parse_cpus reads ("0-3,6")."""
    ranges: list[tuple[int, int]] = []
    for cpu in sorted(cpus):
        if ranges and ranges[-1][1] == cpu - 1:
            ranges[-1] = (ranges[-1][0], cpu)
        else:
            ranges.append((cpu, cpu))
    return ",".join(str(low) if low == high else f"{low}-{high}" for low, high in ranges)


def _normal_priority() -> None:
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def use_normal_priority_executor(loop: asyncio.AbstractEventLoop) -> None:
    """Run the loop's blocking work in threads at normal priority (they would inherit SCHED_FIFO)."""
    loop.set_default_executor(ThreadPoolExecutor(thread_name_prefix="softplc-blocking", initializer=_normal_priority))
