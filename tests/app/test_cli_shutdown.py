"""`softplc run` stopped by real signals, as a real process: the signal is named, a shutdown under
way always finishes (a second signal is ignored), and the exit statuses of docs/runtime.md."""

from __future__ import annotations

import signal
import sqlite3
from pathlib import Path

import pytest

from conftest import REPO
from test_cli import Process, statistics

CORE = REPO / "tests" / "core_programs.py"

COUNTING = f"""
version: 1
tags:
  total: {{type: uint32, retain: true}}
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: count, program: "{CORE}:Counter", bind: {{count: total}}}}
"""

# A program that blocks the loop once, at start: the runtime is in ERROR from then on, until reset.
STALLING = f"""
version: 1
tags:
  armed: {{type: bool, initial: true}}
  done: {{type: uint32}}
runtime:
  stall_after: 200ms
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: block, program: "{CORE}:Blocker", bind: {{armed: armed, done: done}}, params: {{block: 0.5, once: true}}}}
"""


def start(tmp_path: Path, text: str, *options: str) -> Process:
    plant = tmp_path / "plant.yaml"
    plant.write_text(text)
    return Process(["run", str(plant), "--no-status", "--state-dir", str(tmp_path / "state"), *options], tmp_path)


@pytest.mark.parametrize("loop", ["asyncio", "uvloop"])
def test_sigterm_is_reported_as_sigterm_and_stops_cleanly(tmp_path: Path, loop: str) -> None:
    process = start(tmp_path, COUNTING, "--no-servers", "--loop", loop)
    try:
        process.wait_for("press Ctrl-C to stop", timeout=30)
        process.popen.send_signal(signal.SIGTERM)
        code = process.finish(timeout=30)
    finally:
        process.kill()
    output = "\n".join(process.lines)
    assert code == 0, output
    assert "softplc: terminated (SIGTERM): stopping (the servers, then retained values are saved)" in output
    assert "stopped: terminated (SIGTERM) — scanned " in output
    assert "Ctrl-C)" not in output.replace("press Ctrl-C to stop", "")
    assert "Traceback" not in output


def test_a_second_signal_during_the_shutdown_is_ignored_and_the_shutdown_finishes(tmp_path: Path) -> None:
    # The OPC UA server takes about a second to stop: the further signals arrive while it does.
    process = start(tmp_path, COUNTING, "--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--no-modbus")
    try:
        process.wait_for("press Ctrl-C to stop", timeout=60)
        assert any(line.startswith("serving: OPC UA on opc.tcp://127.0.0.1:") for line in process.lines), process.lines
        process.popen.send_signal(signal.SIGTERM)
        process.wait_for("softplc: terminated (SIGTERM): stopping", timeout=30)
        process.popen.send_signal(signal.SIGTERM)
        process.wait_for("received while stopping", timeout=30)
        for again in (signal.SIGINT, signal.SIGTERM):  # more of them: ignored without a word
            process.popen.send_signal(again)
        code = process.finish(timeout=60)
    finally:
        process.kill()
    output = "\n".join(process.lines)
    assert code == 0, output  # not killed by the second SIGTERM, not 130 from the SIGINT
    assert "Traceback" not in output
    notes = [line for line in process.lines if "received while stopping" in line]
    assert notes == ["softplc: SIGTERM received while stopping: ignored, the shutdown under way finishes first (SIGKILL abandons it)"], output
    assert "stopped: terminated (SIGTERM)" in output
    cycles = int(statistics(output)["fast"][2])
    assert cycles > 0
    # the shutdown went to its end: the value saved is the one of the very last cycle
    connection = sqlite3.connect(tmp_path / "state" / "retain.sqlite")
    try:
        saved = int(dict(connection.execute("SELECT name, value FROM retain").fetchall())["total"])
    finally:
        connection.close()
    assert saved == cycles


def test_a_clean_stop_by_signal_exits_0_even_with_an_error_never_reset(tmp_path: Path) -> None:
    process = start(tmp_path, STALLING, "--no-servers")
    try:
        process.wait_for("task fast is stuck in program block", timeout=30)
        process.wait_for("softplc: ERROR: task fast is stuck", timeout=30)  # the loop runs again
        process.popen.send_signal(signal.SIGTERM)
        code = process.finish(timeout=30)
    finally:
        process.kill()
    output = "\n".join(process.lines)
    assert code == 0, output
    assert "softplc: the runtime was in ERROR when it stopped: task fast is stuck in program block for " in output
    assert "program block: FAULTED task fast is stuck in program block" in output


def test_a_run_that_ends_by_itself_in_error_exits_1(tmp_path: Path) -> None:
    process = start(tmp_path, STALLING, "--no-servers", "--duration", "1.5")
    try:
        code = process.finish(timeout=30)
    finally:
        process.kill()
    output = "\n".join(process.lines)
    assert code == 1, output
    assert "stopped: duration of 1.5 s reached" in output
    assert "softplc: the runtime was in ERROR when it stopped: task fast is stuck in program block for " in output
