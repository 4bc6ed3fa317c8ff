"""Logging: timestamps (simulated under --sim), program loggers and faults, -v tracebacks, JSON lines,
a rotating log file, and a client flood limited to a few lines."""

from __future__ import annotations

import asyncio
import json
import logging
import os
import re
import signal
import sys
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from asyncua import Client, ua

from softplc.app.cli import main
from tests.conftest import REPO

PROGRAMS = '''
from softplc import InOut, Param, Program


class Divider(Program):
    """Logs when it starts, then divides by zero once the clock reaches `fault_at`."""

    x = InOut("a number")
    fault_at = Param(2.5, "seconds until the fault")

    def setup(self) -> None:
        self.log.info("ready to divide")

    def scan(self) -> None:
        if self.now >= self.fault_at:
            self.x = 1 / 0


class Chatter(Program):
    """Logs a different line every scan (letters, so no two lines are of one kind)."""

    count = InOut("scans")

    def scan(self) -> None:
        self.count += 1
        word = "".join(chr(97 + (self.count // 26 ** i) % 26) for i in range(4))
        self.log.info("scan %s " + word + " and some padding to make the line longer than a short one", self.count)
'''

PLANT = """
version: 1
plant: {{name: logs}}
tags:
  x: {{type: float64}}
  count1: {{type: uint32}}
  count2: {{type: uint32}}
  count3: {{type: uint32}}
tasks:
  plant:
    interval: 100ms
    programs:
      - name: divider
        program: {programs}:Divider
        bind: {{x: x}}
{chatter}
"""
CHATTER = "".join(f"""      - name: chatter{n}
        program: {{programs}}:Chatter
        bind: {{{{count: count{n}}}}}
""" for n in (1, 2, 3))

LINE = re.compile(r"^(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z) softplc: (DEBUG|INFO|WARNING|ERROR|CRITICAL): (.*) \[([\w.]+)\]$")


def plant_file(directory: Path, chatter: bool = False) -> Path:
    programs = directory / "log_programs.py"
    programs.write_text(textwrap.dedent(PROGRAMS))
    path = directory / "plant.yaml"
    path.write_text(PLANT.format(programs=programs, chatter=CHATTER.format(programs=programs) if chatter else ""))
    return path


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str]) -> Iterator[Callable[..., tuple[int, str, str]]]:
    """`softplc ARGS` in this process; restores the logging set-up afterwards."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level

    def run(*args: object) -> tuple[int, str, str]:
        code = main([str(arg) for arg in args])
        out, err = capsys.readouterr()
        return code, out, err

    yield run
    for handler in root.handlers[:]:
        root.removeHandler(handler)
        if handler not in handlers:
            handler.close()
    root.handlers[:] = handlers
    root.setLevel(level)
    logging.getLogger("asyncua").setLevel(logging.NOTSET)


def log_lines(text: str) -> list[re.Match[str]]:
    return [match for line in text.splitlines() if (match := LINE.match(line))]


def test_text_lines_carry_simulated_time_level_and_the_program_logger(cli, tmp_path: Path) -> None:
    code, _, err = cli("run", plant_file(tmp_path), "--sim", "--duration", "5", "--no-servers")
    assert code == 0, err
    lines = {match.group(3): match for match in log_lines(err)}
    ready = lines["ready to divide"]
    assert (ready.group(1), ready.group(2), ready.group(4)) == ("2026-01-01T00:00:00.000Z", "INFO", "softplc.core.program.divider")
    fault = next(match for text, match in lines.items() if text.startswith("program divider FAULTED"))
    # The fault happens in the scan at simulated 2.5 s, and its line says so; it is the program's own.
    assert (fault.group(1), fault.group(2), fault.group(4)) == ("2026-01-01T00:00:02.500Z", "ERROR", "softplc.core.program.divider")
    assert fault.group(3) == f"program divider FAULTED: ZeroDivisionError: division by zero at {tmp_path / 'log_programs.py'}:16"
    assert "Traceback" not in err  # without -v, the one-line error


@pytest.mark.parametrize("where", ["before", "after"])
def test_v_shows_the_traceback_of_a_program_fault(cli, tmp_path: Path, where: str) -> None:
    arguments = ["run", plant_file(tmp_path), "--sim", "--duration", "5", "--no-servers"]
    arguments = ["-v", *arguments] if where == "before" else [*arguments, "-v"]
    code, _, err = cli(*arguments)
    assert code == 0, err
    lines = err.splitlines()
    index = next(i for i, line in enumerate(lines) if "program divider FAULTED" in line)
    assert lines[index + 1] == "Traceback (most recent call last):"
    trace = lines[index + 1: lines.index("ZeroDivisionError: division by zero", index) + 1]
    assert f'  File "{tmp_path / "log_programs.py"}", line 16, in scan' in trace


def test_json_lines_in_a_log_file(cli, tmp_path: Path) -> None:
    log = tmp_path / "logs" / "softplc.log"
    code, _, err = cli("run", plant_file(tmp_path), "--sim", "--duration", "5", "--no-servers", "--log-format", "json", "--log-file", log)
    assert code == 0, err
    entries = [json.loads(line) for line in log.read_text().splitlines()]  # every line one JSON object
    assert all(set(entry) >= {"time", "level", "logger", "message"} for entry in entries)
    fault = next(entry for entry in entries if entry["message"].startswith("program divider FAULTED"))
    assert fault["time"] == "2026-01-01T00:00:02.500Z" and fault["level"] == "ERROR" and fault["logger"] == "softplc.core.program.divider"
    assert fault["exception"].startswith("Traceback (most recent call last):")
    assert fault["exception"].rstrip().endswith("ZeroDivisionError: division by zero")
    assert {"message": "ready to divide", "logger": "softplc.core.program.divider", "level": "INFO"}.items() <= next(
        entry for entry in entries if entry["message"] == "ready to divide").items()
    # The console keeps the warnings and errors only, as JSON too.
    console = [json.loads(line) for line in err.splitlines() if line.startswith("{")]
    assert [entry["message"] for entry in console] == [fault["message"]]


def test_the_log_file_rotates_by_size_and_keeps_n_files(cli, tmp_path: Path) -> None:
    log = tmp_path / "plant.log"
    code, _, err = cli("run", plant_file(tmp_path, chatter=True), "--sim", "--duration", "8", "--no-servers",
                       "--log-file", log, "--log-max-size", "4KB", "--log-backups", "2")
    assert code == 0, err
    files = sorted(path.name for path in tmp_path.iterdir() if path.name.startswith("plant.log"))
    assert files == ["plant.log", "plant.log.1", "plant.log.2"]
    for name in files:
        assert 0 < (tmp_path / name).stat().st_size <= 4096
    # The newest file holds the newest lines: a chatter's scans count up across the files.
    scans = [[int(n) for n in re.findall(r"scan (\d+) .*\[softplc.core.program.chatter1\]", (tmp_path / name).read_text())]
             for name in ("plant.log.2", "plant.log.1", "plant.log")]
    flat = [n for part in scans for n in part]
    assert flat == sorted(flat) and all(scans)


@pytest.mark.parametrize("size", ["10", "ten", "0KB"])
def test_bad_log_sizes_and_files_are_refused(cli, tmp_path: Path, size: str, capsys) -> None:
    with pytest.raises(SystemExit) as exit:
        cli("run", plant_file(tmp_path), "--log-file", tmp_path / "x.log", "--log-max-size", size)
    assert exit.value.code == 2
    assert "argument --log-max-size:" in capsys.readouterr().err
    (tmp_path / "a-file").write_text("")
    code, _, err = cli("check", plant_file(tmp_path), "--log-file", tmp_path / "a-file" / "x.log")
    assert code == 1 and err.startswith(f"softplc: --log-file {tmp_path / 'a-file' / 'x.log'}: ")


async def test_a_client_flood_of_refused_writes_writes_a_few_lines(tmp_path: Path) -> None:
    """300 writes an anonymous OPC UA client may not make: each is refused (and reported to the audit
    listeners), but the log gets 5 lines and one summary, not 300."""
    log = tmp_path / "plant.log"
    (tmp_path / "plant.yaml").write_text("version: 1\nplant: {name: flood}\ntags:\n  x: {type: int32}\n")
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "softplc.app.cli", "run", str(tmp_path / "plant.yaml"), "--no-status", "--log-file", str(log),
        "--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--modbus-port", "0",
        stderr=asyncio.subprocess.PIPE, env=dict(os.environ, PYTHONPATH=str(REPO)),
    )
    assert process.stderr is not None
    try:
        endpoint = ""
        while not endpoint:
            line = (await asyncio.wait_for(process.stderr.readline(), 60)).decode()
            assert line, "softplc run ended before serving"
            if match := re.search(r"serving: OPC UA on (opc\.tcp://\S+/)", line):
                endpoint = match.group(1)
        async with Client(endpoint) as client:
            node = client.get_node(ua.NodeId("x", await client.get_namespace_index("urn:softplc:tags")))
            for value in range(300):
                results = await client.write_values([node], [ua.DataValue(ua.Variant(value, ua.VariantType.Int32))], raise_on_partial_error=False)
                assert results[0].name == "BadUserAccessDenied"
    finally:
        process.send_signal(signal.SIGINT)
        await asyncio.wait_for(process.wait(), 60)
    refused = [line for line in log.read_text().splitlines() if "write x refused" in line]
    assert len(refused) == 6, refused
    assert all(LINE.match(line) for line in refused)
    assert re.search(r"295 more lines like this left out in the last 10 s \(at most 5 of a kind per 10 s\): "
                     r"opcua:anonymous@127\.0\.0\.1: write x refused: role viewer may not write", refused[-1]), refused[-1]
