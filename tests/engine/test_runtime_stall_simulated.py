"""Stalls on the simulated clock: a simulated run judges a stuck scan by the CPU time the event
loop's thread spent in it, never by wall time, so a busy or paused machine never fails a
simulation (docs/runtime.md, "Stalls"); a scan blocked without computing is caught by a far
longer wall-time bound."""

from __future__ import annotations

import signal
import time
from pathlib import Path

from conftest import REPO

from softplc.app.runtime import Runtime, RuntimeState
from softplc.core.clock import SimClock
from softplc.engine.scan import ProgramState
from softplc.engine.stall import StallDetector
from tests.app.test_cli import Process

CORE = REPO / "tests" / "core_programs.py"


def burning(burn: float, marker: str = "", stall_after: str | None = None) -> str:
    runtime = f"runtime: {{stall_after: {stall_after}}}\n" if stall_after else ""
    return f"""
version: 1
tags:
  armed: {{type: bool, initial: true}}
  done: {{type: uint32}}
{runtime}tasks:
  fast:
    interval: 100ms
    programs:
      - {{name: burn, program: "{CORE}:CpuBurner", bind: {{armed: armed, done: done}}, params: {{burn: {burn}, marker: "{marker}"}}}}
"""


def test_a_simulation_paused_by_the_machine_mid_scan_is_not_a_stall(tmp_path: Path) -> None:
    marker = tmp_path / "burning"
    plant = tmp_path / "plant.yaml"
    plant.write_text(burning(0.3, str(marker)))  # the stall limit: 1 s (10 watchdogs, at least 1 s)
    process = Process(["run", str(plant), "--sim", "--duration", "5", "--no-servers", "--no-status"], tmp_path)
    try:
        deadline = time.monotonic() + 60
        while not marker.exists():  # the burning scan has begun
            assert time.monotonic() < deadline and process.popen.poll() is None, process.lines
            time.sleep(0.005)
        # The machine stalls the process mid-scan for 1.5 s of wall time (a busy CI host, a VM paused).
        process.popen.send_signal(signal.SIGSTOP)
        time.sleep(1.5)  # the stall under test
        process.popen.send_signal(signal.SIGCONT)
        code = process.finish(timeout=60)
    finally:
        process.popen.send_signal(signal.SIGCONT)
        process.kill()
    output = "\n".join(process.lines)
    assert "stuck" not in output and "ERROR" not in output, output
    assert code == 0 and "stopped: duration of 5 s reached" in output, output


def test_a_scan_computing_longer_than_the_limit_is_a_stall_on_the_simulated_clock_too(make_config) -> None:
    runtime = Runtime(make_config(burning(0.5, stall_after="200ms")), SimClock())
    stalls: list[str] = []
    detector = StallDetector(runtime.engine, lambda task, program, message: stalls.append(message), stall_after=0.2, simulated=True)
    detector.start()
    try:
        runtime.engine.start_programs()
        runtime.engine.cycle(runtime.tasks[0], 0.0)
    finally:
        detector.stop()
    assert len(stalls) == 1, stalls
    assert stalls[0].startswith("task fast is stuck in program burn for 0.") and "s of CPU time" in stalls[0]


def test_a_scan_blocked_without_computing_is_a_stall_past_the_wall_time_bound(make_config) -> None:
    runtime = Runtime(make_config(f"""
version: 1
tags:
  armed: {{type: bool, initial: true}}
  done: {{type: uint32}}
tasks:
  fast:
    interval: 100ms
    programs:
      - {{name: block, program: "{CORE}:Blocker", bind: {{armed: armed, done: done}}, params: {{block: 0.6, once: true}}}}
"""), SimClock())
    stalls: list[str] = []
    # The bound is minutes by default; made short here so the test does not wait for it.
    detector = StallDetector(runtime.engine, lambda task, program, message: stalls.append(message), stall_after=0.2, simulated=True, wall_limit=0.3)
    detector.start()
    try:
        runtime.engine.start_programs()
        runtime.engine.cycle(runtime.tasks[0], 0.0)  # time.sleep(0.6): no CPU time, 0.6 s of wall time
    finally:
        detector.stop()
    assert len(stalls) == 1, stalls
    assert stalls[0].startswith("task fast is stuck in program block for 0.") and "without computing" in stalls[0], stalls


async def test_a_simulated_runtime_faults_the_program_that_computes_too_long(make_config) -> None:
    runtime = Runtime(make_config(burning(0.5, stall_after="200ms")), SimClock())
    await runtime.start()
    try:
        while runtime.db.value("done") < 1:
            await runtime.clock.sleep(0.1)
        await runtime.clock.sleep(0.1)
    finally:
        await runtime.stop()
    assert runtime.program("burn").state is ProgramState.FAULTED
    assert runtime.state is RuntimeState.STOPPED and "s of CPU time" in runtime.error
