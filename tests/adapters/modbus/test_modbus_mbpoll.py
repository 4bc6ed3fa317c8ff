"""An independent client (mbpoll, Debian package) against `softplc run` started as a user would."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import REPO
from modbus_helpers import mbpoll_path, polled

PLANT = """
version: 1
tags:
  motor_on:  {type: bool}
  at_home:   {type: bool, access: ro, initial: true}
  speed:     {type: int16, min: -100, max: 100, initial: -42}
  count:     {type: uint16, initial: 7}
  setpoint:  {type: float32, initial: 2.5}
  position:  {type: float32, access: ro, initial: 12.75}
  total:     {type: int32, initial: -100000}
tasks:
  fast: {interval: 10ms}
servers:
  modbus: {unit_id: 5}
"""

UNIT = "5"


class Softplc:
    """`softplc run CONFIG --modbus-port 0` in a subprocess; knows the port it announced."""

    def __init__(self, process: subprocess.Popen[str], port: int, lines: list[str]) -> None:
        self.process = process
        self.port = port
        self.lines = lines

    def mbpoll(self, *arguments: str, unit: str = UNIT) -> tuple[int, str]:
        """Run mbpoll once against the server; returns (exit code, stdout + stderr)."""
        command = [mbpoll_path(), "-m", "tcp", "-a", unit, "-p", str(self.port), "-1", "-o", "2", *arguments]
        done = subprocess.run(command, capture_output=True, text=True, timeout=15)
        return done.returncode, done.stdout + done.stderr


@pytest.fixture(scope="module")
def softplc(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Softplc]:
    """One `softplc run` for the whole module (starting one takes ~2 s)."""
    folder: Path = tmp_path_factory.mktemp("mbpoll")
    config = folder / "tagdb.yaml"
    config.write_text(PLANT)
    process = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "run", str(config), "--modbus-port", "0", "--no-opcua", "--no-status",
         "--state-dir", str(folder / "state")],
        cwd=str(REPO), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    watchdog = threading.Timer(30, process.kill)  # a hung start fails the test instead of hanging it
    watchdog.start()
    lines: list[str] = []
    port = None
    assert process.stderr is not None
    while port is None:
        line = process.stderr.readline()
        if not line:
            watchdog.cancel()
            raise AssertionError("softplc run exited before serving:\n" + "".join(lines))
        lines.append(line)
        match = re.search(r"serving: Modbus TCP on 127\.0\.0\.1:(\d+) unit 5", line)
        if match:
            port = int(match.group(1))
    watchdog.cancel()
    yield Softplc(process, port, lines)
    if process.poll() is None:
        process.kill()
        process.wait(10)


def test_mbpoll_reads_every_table(softplc):
    code, out = softplc.mbpoll("-t", "4", "-r", "1", "-c", "2", "127.0.0.1")
    assert code == 0, out
    assert polled(out) == {1: "65494", 2: "7"}  # -42 as an unsigned register, then 7
    assert "(-42)" in out
    code, out = softplc.mbpoll("-t", "4:float", "-B", "-r", "3", "127.0.0.1")
    assert code == 0 and polled(out) == {3: "2.5"}, out
    code, out = softplc.mbpoll("-t", "4:int", "-B", "-r", "5", "127.0.0.1")
    assert code == 0 and polled(out) == {5: "-100000"}, out
    code, out = softplc.mbpoll("-t", "3:float", "-B", "-r", "1", "127.0.0.1")
    assert code == 0 and polled(out) == {1: "12.75"}, out
    code, out = softplc.mbpoll("-t", "0", "-r", "1", "127.0.0.1")
    assert code == 0 and polled(out) == {1: "0"}, out
    code, out = softplc.mbpoll("-t", "1", "-r", "1", "127.0.0.1")
    assert code == 0 and polled(out) == {1: "1"}, out


def test_mbpoll_sees_the_exception_codes(softplc):
    code, out = softplc.mbpoll("-t", "4", "-r", "100", "127.0.0.1")
    assert code != 0 and "Illegal data address" in out, out
    code, out = softplc.mbpoll("-t", "4", "-r", "1", "127.0.0.1", "500")  # speed max 100
    assert code != 0 and "Illegal data value" in out, out
    code, out = softplc.mbpoll("-t", "4:int", "-B", "-r", "6", "127.0.0.1", "1")  # half of 'total' + beyond
    assert code != 0 and "Illegal data address" in out, out
    code, out = softplc.mbpoll("-t", "4", "-r", "1", "127.0.0.1", unit="9")
    assert code != 0 and "Target device failed to respond" in out, out
    # nothing was touched by the rejected writes
    code, out = softplc.mbpoll("-t", "4", "-r", "1", "-c", "6", "127.0.0.1")
    assert polled(out) == {1: "65494", 2: "7", 3: "16416", 4: "0", 5: "65534", 6: "31072"}, out


def test_mbpoll_writes_and_reads_back_after_the_scan(softplc):
    code, out = softplc.mbpoll("-t", "4", "-r", "1", "127.0.0.1", "65519")  # -17 as a register
    assert code == 0 and "Written 1 references" in out, out
    code, out = softplc.mbpoll("-t", "4:float", "-B", "-r", "3", "127.0.0.1", "--", "-6.5")
    assert code == 0, out
    code, out = softplc.mbpoll("-t", "0", "-r", "1", "127.0.0.1", "1")
    assert code == 0, out
    deadline = time.monotonic() + 5
    while True:  # the writes are applied at the next cycle boundary (10 ms task)
        _, speed = softplc.mbpoll("-t", "4", "-r", "1", "127.0.0.1")
        _, setpoint = softplc.mbpoll("-t", "4:float", "-B", "-r", "3", "127.0.0.1")
        _, motor = softplc.mbpoll("-t", "0", "-r", "1", "127.0.0.1")
        if (polled(speed).get(1), polled(setpoint).get(3), polled(motor).get(1)) == ("65519", "-6.5", "1"):
            break
        assert time.monotonic() < deadline, (speed, setpoint, motor)
        time.sleep(0.01)


def test_softplc_run_stops_cleanly_on_ctrl_c(softplc):
    softplc.process.send_signal(signal.SIGINT)
    assert softplc.process.wait(15) == 0
    assert softplc.process.stderr is not None
    rest = softplc.process.stderr.read()
    assert "stopped: interrupted (SIGINT, Ctrl-C)" in rest
    assert "Traceback" not in "".join(softplc.lines) + rest
