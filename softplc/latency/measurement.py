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
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from softplc.latency.credentials import client_security, with_opcua_login
from softplc.latency.endpoint import EndpointError, parse_endpoint
from softplc.latency.plant import handshake_config, scenario_durations

log = logging.getLogger(__name__)

LOOPBACK = {"127.0.0.1", "localhost", "::1"}
Progress = Callable[["Measurement"], None]



@dataclass
class Target:
    """What to measure and how (the `softplc latency` options of one protocol × scenario)."""

    protocol: str  # opcua | modbus
    scenario: str  # slow | average | fast
    scan: float = 0.01  # the PLC's scan in s (ours; for --endpoint, what the remote PLC runs)
    client_mode: str | None = None  # subscription | poll; None: subscription for OPC UA, poll for Modbus
    endpoint: str | None = None  # None: start our runtime
    samples: int | None = None
    duration: float | None = None
    tags: list[str] = field(default_factory=list)  # ROLE=ADDRESS overrides for --endpoint
    namespace: str | None = None
    security: str | None = None
    user: str | None = None
    password: str | None = None
    unit_id: int = 1
    word_order: str = "big"
    poll_interval_ms: float = 1.0
    publishing_interval_ms: float = 0.0
    timeout: float | None = None  # per Ready; default: the longest task + 1 s
    loop: str = "asyncio"

    @property
    def mode(self) -> str:
        return self.client_mode or ("subscription" if self.protocol == "opcua" else "poll")

    @property
    def label(self) -> str:
        return f"{self.protocol} {self.scenario}"

    def ready_timeout(self) -> float:
        if self.timeout is not None:
            return self.timeout
        return max(scenario_durations(self.scenario)) + 1.0 + 3 * self.scan


@dataclass
class Sample:
    """One answered handshake with its client timestamps (monotonic s) and the PLC's figures."""

    index: int
    task_id: int
    status: str  # ok | missed | start (the warm-up answer that started the sequence)
    ready_stamp: float | None
    t_seen: float
    t_sent: float
    t_done: float
    plc_delay_ms: float | None
    plc_delay_scans: int | None
    plc_handshakes: int | None

    @classmethod
    def from_event(cls, event: dict[str, Any]) -> Sample:
        return cls(**{name: event.get(name) for name in cls.__dataclass_fields__})  # type: ignore[arg-type]

    def hires_ms(self, same_clock: bool) -> float | None:
        """Ready set in the PLC → TaskID write acknowledged by it: the protocol's share of the delay."""
        if not same_clock or self.ready_stamp is None:
            return None
        return (self.t_done - self.ready_stamp) * 1000.0

    def notify_ms(self, same_clock: bool) -> float | None:
        """Ready set in the PLC → the client saw it (push or poll)."""
        if not same_clock or self.ready_stamp is None:
            return None
        return (self.t_seen - self.ready_stamp) * 1000.0

    def respond_ms(self) -> float:
        """The client saw Ready → its write was acknowledged."""
        return (self.t_done - self.t_seen) * 1000.0


@dataclass
class Measurement:
    """Everything one run produced, counted."""

    target: Target
    label: str = ""  # shown instead of the protocol in reports (e.g. a baseline's name)
    endpoint: str = ""
    same_clock: bool = False
    driver: str = ""
    samples: list[Sample] = field(default_factory=list)
    warmup: list[Sample] = field(default_factory=list)
    timeouts: int = 0
    missed: int = 0  # a Ready never answered, or an answer the PLC did not take
    unreported: int = 0  # answered, but the client died before reporting it
    foreign: int = 0  # switches the PLC counted that another client made
    errors: list[str] = field(default_factory=list)
    client_pid: int | None = None
    client_exit: int | None = None
    client_stderr: list[str] = field(default_factory=list)
    started: float = field(default_factory=time.time)
    wall_seconds: float = 0.0
    plc_task: dict[str, Any] = field(default_factory=dict)  # scan statistics of our runtime
    conditions: dict[str, Any] = field(default_factory=dict)

    connected: bool = False  # the client connected and said hello
    ended: str = ""  # why the run ended: complete, interrupted by the user, client died (…), …
    activity: str = ""  # what the run is waiting for now, when that is not the client's next report
    missed_notes: list[str] = field(default_factory=list)  # context of missed handshakes found after the client
    client_gone_at: float | None = None  # monotonic time the client's output ended

    @property
    def ok_samples(self) -> list[Sample]:
        return [sample for sample in self.samples if sample.status == "ok"]

    @property
    def complete(self) -> bool:
        return self.client_exit == 0 and not self.errors

    @property
    def not_attempted(self) -> int | None:
        """Requested samples never attempted (the run ended first); None for a --duration run."""
        if self.target.samples is None or self.target.duration is not None:
            return None
        attempted = len(self.samples) + len(self.missed_notes) + self.unreported
        return max(0, self.target.samples - attempted)


def is_loopback(endpoint: str) -> bool:
    try:
        return parse_endpoint(endpoint).host in LOOPBACK
    except EndpointError:
        return False


def client_command(target: Target, endpoint: str) -> list[str]:
    """argv of the client process."""
    argv = [sys.executable, "-m", "softplc.latency.client", "--protocol", target.protocol, "--endpoint", endpoint,
            "--mode", target.mode, "--timeout", f"{target.ready_timeout():g}",
            "--poll-interval", f"{target.poll_interval_ms:g}", "--publishing-interval", f"{target.publishing_interval_ms:g}",
            "--unit-id", str(target.unit_id), "--word-order", target.word_order]
    if target.samples is not None:
        argv += ["--samples", str(target.samples)]
    if target.duration is not None:
        argv += ["--duration", f"{target.duration:g}"]
    for tag in target.tags:
        argv += ["--tag", tag]
    for option, value in (("--namespace", target.namespace), ("--security", target.security), ("--user", target.user)):
        if value:
            argv += [option, value]
    return argv


async def measure(target: Target, progress: Progress | None = None, stop: asyncio.Event | None = None) -> Measurement:
    """Run one measurement to the end (or until the client dies or hangs, or `stop` is set) and count everything."""
    result = Measurement(target, conditions=conditions(target))
    cpu_start = cpu_counters()
    try:
        await _measure(target, result, progress or (lambda run: None), stop or asyncio.Event())
    finally:
        finish_conditions(result, cpu_start)
    return result


def interrupted(result: Measurement, stop: asyncio.Event, when: str = "") -> bool:
    """True (and recorded) when the user has asked to stop."""
    if not stop.is_set():
        return False
    if not result.ended:
        result.ended = "interrupted by the user"
        result.errors.append("interrupted by the user" + when)
    return True


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
    from softplc.adapters import build_adapters
    from softplc.clock import RealClock
    from softplc.runtime import Runtime

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
            if not interrupted(result, stop, " before the client started"):
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
    }
