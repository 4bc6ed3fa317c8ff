"""`softplc run` stopped by real signals, as a real process: the signal is named, a shutdown under
way always finishes (a second signal is ignored), and the exit statuses of docs/runtime.md."""

from __future__ import annotations

import re
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO

from tests.app.test_cli import FREE_PORTS, SOFTPLC, Process, statistics

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


# A second signal at these delays after the first: the shutdown may be done by then, with the
# interpreter still exiting (threads joined, files closed); the process must not die of it.
SECOND_SIGNAL_DELAYS = (0.05, 0.2, 0.5)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_second_signal_soon_after_the_first_never_kills_the_process(tmp_path: Path, signum: int) -> None:
    for delay in SECOND_SIGNAL_DELAYS:
        folder = tmp_path / f"after-{delay}"
        folder.mkdir()
        process = start(folder, COUNTING, *FREE_PORTS)
        try:
            process.wait_for("press Ctrl-C to stop", timeout=60)
            process.popen.send_signal(signum)
            time.sleep(delay)  # the delay under test (not a wait for a condition)
            process.popen.send_signal(signum)
            code = process.finish(timeout=60)
        finally:
            process.kill()
        output = "\n".join(process.lines)
        assert code == 0, f"second {signal.Signals(signum).name} {delay} s after the first: exit status {code}\n{output}"
        assert "Traceback" not in output
        assert sum("received while stopping" in line for line in process.lines) <= 1, output


# A Ctrl-C at a terminal reaches a process whose SIGINT has its default action. A test run started
# in the background of a non-interactive shell ignores SIGINT, and its children inherit that (Python
# then installs no KeyboardInterrupt): the command is exec'd with the default action restored, in
# the same process (the signal the test sends still reaches it).
AS_FROM_A_TERMINAL = [sys.executable, "-c", "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                      "os.execv(sys.argv[1], sys.argv[1:])"]


def _softplc_imported(process: subprocess.Popen[str], lines: list[str], timeout: float = 60) -> None:
    """Wait until the package `softplc` is imported: softplc's own code runs from here (before it,
    Python's start-up reports a Ctrl-C itself, e.g. "Failed checking if argv[0] is an import path entry")."""
    assert process.stderr is not None
    deadline = time.monotonic() + timeout
    for line in process.stderr:
        lines.append(line)
        if line.startswith("import time:") and re.search(r"\|\s+softplc$", line.rstrip()):
            return
        assert time.monotonic() < deadline, "Python did not start"
    raise AssertionError(f"the process ended during start-up: {lines}")


# From 20 ms after the package is imported: before that, the console script pip wrote is still
# on its own first line (a re.sub) before it calls softplc.main, and a Ctrl-C there is Python's.
@pytest.mark.parametrize("delay", [0.02, 0.05, 0.1, 0.2, 0.4])
def test_ctrl_c_while_softplc_is_starting_exits_quietly(tmp_path: Path, delay: float) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(COUNTING)
    # -X importtime tells when the package is imported: the Ctrl-C lands in softplc's own start
    # (imports, the configuration, the runtime starting), `delay` seconds later.
    process = subprocess.Popen(
        [*AS_FROM_A_TERMINAL, sys.executable, "-X", "importtime", SOFTPLC, "run", str(plant), "--no-status", "--no-servers",
         "--state-dir", str(tmp_path / "state")],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    lines: list[str] = []
    try:
        _softplc_imported(process, lines)
        time.sleep(delay)  # the delay under test
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    output = "".join(lines) + out + err
    messages = "\n".join(line for line in output.splitlines() if not line.startswith("import time:"))
    assert "Traceback" not in messages and "KeyboardInterrupt" not in messages, messages
    # Before `run` takes over the signals: 130; after, a clean stop as soon as it has started: 0.
    assert process.returncode in (130, 0), f"exit status {process.returncode}\n{messages}"
    if process.returncode == 0:
        assert "stopped: interrupted (SIGINT, Ctrl-C)" in messages, messages
