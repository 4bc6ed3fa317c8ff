"""One latency measurement: a PLC (our runtime, or --endpoint) and the client process answering it.

By default the handshake plant runs here, in real time, with only the protocol under test
served on a free loopback port; the client is a separate Python process (`softplc.latency.
client`) that speaks the protocol like any external program. Its JSON lines become `Sample`s.

Nothing is dropped silently. When the client dies (or hangs, and is killed) before finishing,
the PLC is read once more over the protocol: a Ready left unanswered is a *missed* handshake,
noted with when it was set, and switches the PLC counted that the client never reported are
*unreported*. What was requested but never attempted is reported as such.
"""

from __future__ import annotations

import asyncio
import logging
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from softplc.latency.credentials import client_security, with_opcua_login
from softplc.latency.endpoint import EndpointError, parse_endpoint
from softplc.latency.plant import handshake_config
from softplc.latency.results import Measurement, Progress, Sample, interrupted
from softplc.latency.target import Target
from softplc.util.realtime import format_cpus

log = logging.getLogger(__name__)

LOOPBACK = {"127.0.0.1", "localhost", "::1"}

__all__ = ["Measurement", "Sample", "Target", "conditions", "cpu_counters", "finish_conditions", "is_loopback", "measure"]


def is_loopback(endpoint: str) -> bool:
    try:
        return parse_endpoint(endpoint).host in LOOPBACK
    except EndpointError:
        return False


async def measure(target: Target, progress: Progress | None = None, stop: asyncio.Event | None = None) -> Measurement:
    """Run one measurement to the end (or until the client dies or hangs, or `stop` is set) and count everything."""
    result = Measurement(target, conditions=conditions(target))
    cpu_start = cpu_counters()
    try:
        await _measure(target, result, progress or (lambda run: None), stop or asyncio.Event())
    finally:
        finish_conditions(result, cpu_start)
    return result


async def _measure(target: Target, result: Measurement, progress: Progress, stop: asyncio.Event) -> None:
    from softplc.latency.client_process import run_client

    if interrupted(result, stop, " before the run started"):
        return
    if target.endpoint is not None:
        result.endpoint = target.endpoint
        result.same_clock = is_loopback(target.endpoint)
        target = client_security(target)
        result.target = target
        await run_client(target, result, progress, stop)
        return
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.core.clock import RealClock

    with tempfile.TemporaryDirectory(prefix="softplc-latency-") as state_dir:
        state = Path(state_dir)
        if target.protocol == "opcua":
            config = handshake_config(target.scenario, target.scan, opcua_endpoint="opc.tcp://127.0.0.1:0/softplc/")
            target = with_opcua_login(target, state)
            result.target = target
        else:
            config = handshake_config(target.scenario, target.scan, modbus_port=0)
        runtime = Runtime(config, RealClock(), state_dir=state)
        for adapter in build_adapters(config, None):
            runtime.add_adapter(adapter)
        await runtime.start()
        try:
            server: Any = next(a for a in runtime.adapters if a.name == target.protocol)
            if target.protocol == "modbus":
                result.endpoint = f"127.0.0.1:{server.port}"
            else:
                result.endpoint = server.endpoint
            result.same_clock = True
            if interrupted(result, stop, " before the client started"):
                pass
            elif target.mode == "link":
                from softplc.latency.link_peer import run_link_peer

                await run_link_peer(target, result, progress, stop, runtime, state)
            else:
                await run_client(target, result, progress, stop)
        finally:
            task = runtime.tasks[0]
            result.plc_task = {"interval_ms": task.interval * 1e3, "cycles": task.stats.cycles, "overruns": task.stats.overruns,
                               "start_latency_ms": task.stats.latency.summary(), "scan_ms": task.stats.scan.summary(),
                               "program_state": task.programs[0].state.value, "program_error": task.programs[0].error,
                               **_plc_counters(runtime)}
            await runtime.stop()


def _plc_counters(runtime: Any) -> dict[str, Any]:
    """The handshake program's own counters of things a client did wrong (programs/handshake.py)."""
    counters = {}
    for key, tag in (("unexpected_taskids", "Unexpected"), ("ready_raised_again", "BadAnswers")):
        try:
            counters[key] = runtime.db.value(tag)
        except KeyError:
            pass
    return counters


def cpu_counters() -> list[int] | None:
    """The machine's CPU time counters (Linux /proc/stat: user … steal), or None elsewhere."""
    try:
        with open("/proc/stat") as stat:
            return [int(value) for value in stat.readline().split()[1:9]]
    except (OSError, ValueError):
        return None


def finish_conditions(result: Measurement, start: list[int] | None) -> None:
    """Add what the CPUs did during the run: busy (all processes) and stolen by the hypervisor."""
    end = cpu_counters()
    try:
        result.conditions["load_average_end"] = [round(value, 2) for value in os.getloadavg()]
    except OSError:
        pass
    if start is None or end is None:
        return
    delta = [b - a for a, b in zip(start, end)]
    total = sum(delta) or 1
    idle = delta[3] + delta[4]
    result.conditions["cpu_busy_percent"] = round(100.0 * (total - idle) / total, 1)
    result.conditions["cpu_steal_percent"] = round(100.0 * delta[7] / total, 1)


def conditions(target: Target) -> dict[str, Any]:
    """The machine's state, so figures can be judged (CPU contention distorts them)."""
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    return {
        "cpus": os.cpu_count(),
        "load_average_1_5_15": [round(value, 2) for value in load],
        "python": sys.version.split()[0],
        "platform": sys.platform,
        "event_loop": target.loop,
        # Where the two sides ran: the CPUs this process (our runtime, if any) and the client may use
        # (asked for here; replaced by what the client reports when it says hello).
        "runtime_cpus": format_cpus(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else "",
        "client_cpus": format_cpus(target.client_cpus) if target.client_cpus is not None else "",
    }
