"""The command line: check, tags, schema, run (--until, --loop, --speed, Ctrl-C), --help."""

from __future__ import annotations

import csv
import io
import json
import logging
import os
import queue
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import jsonschema
import pytest
import yaml
from conftest import REPO

from softplc.app.cli import main
from softplc.config import load_config

SOFTPLC = str(Path(sys.executable).parent / "softplc")
# Real-time runs serve on free ports: other plants on this machine may hold the default ones.
FREE_PORTS = ["--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--modbus-port", "0", "--hmi-port", "0"]
PROGRAMS = REPO / "tests" / "configs" / "sample_programs.py"

PLANT = f"""
version: 1
plant: {{name: cli-test}}
templates:
  line:
    instances: [l1, l2]
    tags:
      a: {{type: float64, initial: 1, unit: m}}
      b: {{type: float64, initial: 2}}
      total: {{type: float64, access: ro}}
      scans: {{type: uint32}}
tags:
  flag: {{type: bool, description: "a, flag"}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: sum_{{line}}
        program: {PROGRAMS}:Summer
        for_each: line
        bind: {{parts: ["{{line}}_a", "{{line}}_b"], total: "{{line}}_total", scans: "{{line}}_scans"}}
  slow:
    interval: 1s
    priority: 20
"""


@pytest.fixture
def plant(tmp_path: Path) -> Path:
    path = tmp_path / "plant.yaml"
    path.write_text(PLANT)
    return path


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str]) -> Iterator[Callable[..., tuple[int, str, str]]]:
    """Run `softplc ARGS` in-process; returns (exit code, stdout, stderr). Restores logging."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level

    def run(*args: str) -> tuple[int, str, str]:
        try:
            code = main([str(arg) for arg in args])
        except SystemExit as exit:  # argparse refused an option
            code = int(exit.code or 0)
        out, err = capsys.readouterr()
        return code, out, err

    yield run
    root.handlers[:] = handlers
    root.setLevel(level)


def statistics(output: str) -> dict[str, list[str]]:
    """The per-task statistics table printed on exit: task name → its columns."""
    lines = output.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("task ") and "interval" in line)
    rows = {}
    for line in lines[start + 2:]:
        if not line.strip() or line.startswith("program "):
            break
        rows[line.split()[0]] = line.split()
    return rows


# -- check / tags / schema ------------------------------------------------------------------


def test_check_prints_a_one_line_summary(cli, plant: Path) -> None:
    code, out, err = cli("check", plant)
    assert code == 0
    assert out == f"{plant}: OK — 9 tags, 2 tasks (fast 10ms, slow 1s), 2 programs\n"


def test_check_default_plant_from_its_folder() -> None:
    result = subprocess.run([SOFTPLC, "check"], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 1 and lines[0].startswith("tagdb.yaml: OK — ")
    config = load_config(REPO / "tagdb.yaml")
    assert f"{len(config.tags)} tags, {len(config.tasks)} tasks" in lines[0]


def test_tags_json_csv_table(cli, plant: Path) -> None:
    code, out, _ = cli("tags", plant, "--format", "json")
    assert code == 0
    rows = json.loads(out)
    by_name = {row["name"]: row for row in rows}
    assert list(by_name)[:9] == ["l1_a", "l1_b", "l1_total", "l1_scans", "l2_a", "l2_b", "l2_total", "l2_scans", "flag"]
    assert by_name["l1_a"] == {
        "name": "l1_a", "type": "float64", "initial": 1.0, "unit": "m", "access": "rw", "min": None,
        "max": None, "retain": False, "group": "Lines/l1", "description": "",
    }
    assert by_name["l2_total"]["access"] == "ro"
    # system tags are listed too, unless --no-system
    assert "_sys.state" in by_name and "_sys.fast.latency_ms_p99" in by_name and "_sys.fast.sum_l2.state" in by_name
    _, out, _ = cli("tags", plant, "--format", "json", "--no-system")
    assert [row["name"] for row in json.loads(out)] == list(by_name)[:9]

    code, out, _ = cli("tags", plant, "--format", "csv")
    assert code == 0
    csv_rows = list(csv.DictReader(io.StringIO(out)))
    assert [row["name"] for row in csv_rows] == list(by_name)
    assert csv_rows[8]["description"] == "a, flag"  # quoted properly
    assert csv_rows[0]["initial"] == "1.0"

    code, out, _ = cli("tags", plant, "--no-system")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].split() == ["name", "type", "initial", "unit", "access", "min", "max", "retain", "group", "description"]
    assert set(lines[1]) == {"-", " "}
    assert len(lines) == 2 + 9
    assert lines[2].split() == ["l1_a", "float64", "1.0", "m", "rw", "Lines/l1"]


def test_schema_command_prints_a_valid_json_schema_the_default_plant_meets(cli) -> None:
    code, out, _ = cli("schema")
    assert code == 0
    schema = json.loads(out)
    jsonschema.Draft202012Validator.check_schema(schema)
    plant = yaml.safe_load((REPO / "tagdb.yaml").read_text())
    jsonschema.Draft202012Validator(schema).validate(plant)
    # Editors are told about malformed durations too.
    bad = {"version": 1, "tasks": {"a": {"interval": "10 parsecs"}, "b": {"interval": -1}, "c": {"interval": "250us"}}}
    assert sorted(error.json_path for error in jsonschema.Draft202012Validator(schema).iter_errors(bad)) == [
        "$.tasks.a.interval", "$.tasks.b.interval"]


@pytest.mark.parametrize("command", [[], ["run"], ["check"], ["tags"], ["schema"]])
def test_help_everywhere(cli, command: list[str]) -> None:
    code, out, _ = cli(*command, "--help")
    assert code == 0 and out.startswith("usage: softplc")


def test_run_help_mentions_loop_choice(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "--loop {asyncio,uvloop}" in capsys.readouterr().out


# -- run: --until, --speed, --loop ----------------------------------------------------------


def test_run_until_a_tag_condition(cli, plant: Path, tmp_path: Path) -> None:
    code, _, err = cli("run", plant, "--sim", "--until", "l1_scans >= 25 and l2_total == 3", "--no-status", "--state-dir", tmp_path)
    assert code == 0, err
    # cycles at 0, 10, ..., 240 ms: the 25th ends the run at 0.24 s
    assert "stopped: condition met: l1_scans >= 25 and l2_total == 3 — scanned 0.2 s of simulated time" in err
    assert statistics(err)["fast"][2] == "25"


def test_run_until_a_system_tag(cli, plant: Path, tmp_path: Path) -> None:
    code, _, err = cli("run", plant, "--sim", "--until", "_sys.fast.cycles >= 30", "--no-status", "--state-dir", tmp_path)
    assert code == 0, err
    # system tags are published every 0.5 s, so the condition is seen at 0.5 s
    assert "stopped: condition met: _sys.fast.cycles >= 30 — scanned 0.5 s of simulated time" in err


@pytest.mark.parametrize(
    ("until", "message"),
    [
        ("l1_scan >= 3", "softplc: --until: unknown tag 'l1_scan' in condition (did you mean 'l1_scans'?)"),
        ("L1_Scans >= 3", "softplc: --until: unknown tag 'L1_Scans' in condition (did you mean 'l1_scans'?)"),
        ("_sys.fast.cycle > 3", "softplc: --until: unknown tag '_sys.fast.cycle' in condition (did you mean '_sys.fast.cycles'?)"),
        ("l1_scans >=", "softplc: --until: cannot parse 'l1_scans >=': invalid syntax"),
        ("__import__('os')", "softplc: --until: not allowed in a condition: \"__import__('os')\""),
    ],
)
def test_run_until_errors(cli, plant: Path, until: str, message: str) -> None:
    code, _, err = cli("run", plant, "--sim", "--until", until)
    assert code == 2
    assert err.strip() == message


def test_speed_needs_sim_and_must_be_positive(cli, plant: Path) -> None:
    code, _, err = cli("run", plant, "--speed", "10", "--duration", "1")
    assert code == 1 and "--speed needs --sim" in err
    for bad in ("0", "-2", "nan", "inf", "fast"):
        code, _, err = cli("run", plant, "--sim", "--speed", bad, "--duration", "1")
        assert code == 2 and "argument --speed: " in err, (bad, err)
    for bad in ("0", "-5", "nan", "inf"):
        code, _, err = cli("run", plant, "--sim", "--duration", bad)
        assert code == 2 and "argument --duration: must be a positive number" in err, (bad, err)


@pytest.mark.parametrize("loop", ["asyncio", "uvloop"])
def test_run_on_either_event_loop(cli, plant: Path, tmp_path: Path, loop: str) -> None:
    code, _, err = cli("run", plant, "--sim", "--duration", "2", "--loop", loop, "--no-status", "--state-dir", tmp_path)
    assert code == 0, err
    assert f"{loop} event loop" in err.splitlines()[0]
    assert statistics(err)["fast"][2] == "200"  # 0, 10, ..., 1990 ms


# -- run as a real process: Ctrl-C and the default plant ------------------------------------


class Process:
    """A `softplc` subprocess whose merged output is read line by line in a thread."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.popen = subprocess.Popen(
            [SOFTPLC, *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self._queue.put(line.rstrip("\n"))
        self._queue.put(None)

    def wait_for(self, text: str, timeout: float) -> None:
        """Wait until a line containing `text` has been printed."""
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"no line with {text!r} within {timeout} s; output so far: {self.lines}")
            try:
                line = self._queue.get(timeout=remaining)
            except queue.Empty:
                continue
            if line is None:
                raise AssertionError(f"process ended before printing {text!r}: {self.lines}")
            self.lines.append(line)

    def finish(self, timeout: float) -> int:
        code = self.popen.wait(timeout=timeout)
        while (line := self._queue.get(timeout=timeout)) is not None:
            self.lines.append(line)
        return code

    def kill(self) -> None:
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait()


@pytest.mark.parametrize("loop", ["asyncio", "uvloop"])
def test_ctrl_c_stops_cleanly_and_prints_statistics(plant: Path, tmp_path: Path, loop: str) -> None:
    process = Process(["run", str(plant), "--no-status", "--loop", loop, "--state-dir", str(tmp_path), *FREE_PORTS], tmp_path)
    try:
        process.wait_for("press Ctrl-C to stop", timeout=30)
        process.popen.send_signal(signal.SIGINT)
        code = process.finish(timeout=30)
    finally:
        process.kill()
    output = "\n".join(process.lines)
    assert code == 0, output
    assert "Traceback" not in output
    assert "softplc: interrupted (SIGINT, Ctrl-C): stopping" in output
    assert "stopped: interrupted (SIGINT, Ctrl-C)" in output
    header = next(line for line in process.lines if line.startswith("task "))
    assert "latency ms min/mean/p99/max" in header and "overruns" in header
    rows = statistics(output)
    assert set(rows) == {"fast", "slow"}
    assert rows["fast"][1] == "10ms" and int(rows["fast"][2]) >= 1


def test_default_plant_runs_600_simulated_seconds(tmp_path: Path) -> None:
    started = time.monotonic()
    # --no-servers: the default plant's servers use fixed ports, which parallel tests may hold
    process = Process(["run", "--sim", "--duration", "600", "--no-servers", "--no-status", "--state-dir", str(tmp_path)], REPO)
    try:
        code = process.finish(timeout=120)
    finally:
        process.kill()
    wall = time.monotonic() - started
    output = "\n".join(process.lines)
    print(f"softplc run --sim --duration 600 (default plant, --no-servers): {wall:.1f} s wall time")
    assert code == 0, output
    assert "stopped: duration of 600 s reached — scanned 600.0 s of simulated time" in output
    config = load_config(REPO / "tagdb.yaml")
    for task in config.tasks:
        cycles = round(600 / task.interval)
        row = statistics(output)[task.name]
        assert int(row[2]) == cycles and int(row[3]) == 0  # every release ran, no overruns


def test_plant_file_is_dedented() -> None:
    # guards the PLANT text above: YAML indentation is significant
    assert textwrap.dedent(PLANT) == PLANT


def test_rt_priority_out_of_range_is_a_clear_error(tmp_path: Path, plant: Path) -> None:
    result = subprocess.run([SOFTPLC, "run", str(plant), "--rt-priority", "500", "--duration", "0.1"],
                            capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 1
    assert result.stderr.strip() == "softplc: --rt-priority: the real-time priority must be between 1 and 99, not 500"


def test_rt_priority_runs_or_says_why_not(tmp_path: Path, plant: Path) -> None:
    result = subprocess.run(
        [SOFTPLC, "run", str(plant), "--rt-priority", "5", "--duration", "0.3", "--state-dir", str(tmp_path), "--no-status", *FREE_PORTS],
        capture_output=True, text=True, timeout=60, cwd=tmp_path,
    )
    if result.returncode == 1:  # without root or CAP_SYS_NICE: refused with the remedy
        assert "softplc: --rt-priority: not permitted to use real-time scheduling" in result.stderr
    else:
        assert result.returncode == 0, result.stderr
        assert "stopped: duration of 0.3 s reached" in result.stderr


def test_cpus_keeps_the_runtime_there_and_refuses_what_the_machine_lacks(tmp_path: Path, plant: Path) -> None:
    result = subprocess.run([SOFTPLC, "run", str(plant), "--cpus", "0-999", "--duration", "0.1"],
                            capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 1
    assert result.stderr.startswith("softplc: --cpus: there is no CPU ") and "this machine has CPU 0" in result.stderr
    result = subprocess.run([SOFTPLC, "run", str(plant), "--cpus", "1-0"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 2
    assert "argument --cpus: '1-0': a range goes from the lower CPU number to the higher one" in result.stderr
    last = max(os.sched_getaffinity(0))  # a CPU this test may use, the last (the runtime starts on all of them)
    process = subprocess.Popen([SOFTPLC, "run", str(plant), "--cpus", str(last), "--duration", "60", "--state-dir", str(tmp_path),
                                "--no-status", *FREE_PORTS], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        assert process.stderr is not None
        for line in process.stderr:  # the runtime lists what it serves once it has started
            if line.startswith("serving:"):
                break
        assert process.poll() is None, "softplc run ended early"
        assert os.sched_getaffinity(process.pid) == {last}
    finally:
        process.terminate()
        process.communicate(timeout=60)


def test_a_simulated_run_neither_restores_nor_saves_retained_values(cli, tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(PLANT.replace("scans: {type: uint32}", "scans: {type: uint32, retain: true}"))
    state = tmp_path / "state"
    for _ in range(2):  # the same result both times: the first run left nothing behind
        code, _, err = cli("run", plant, "--sim", "--until", "l1_scans >= 50", "--no-status", "--state-dir", state)
        assert code == 0, err
        assert "condition met: l1_scans >= 50 — scanned 0.5 s of simulated time" in err
    assert not (state / "retain.sqlite").exists()
    code, _, err = cli("run", plant, "--duration", "0.3", "--no-status", "--state-dir", state, *FREE_PORTS)  # real time: retained
    assert code == 0, err
    assert (state / "retain.sqlite").exists()


def test_where_it_serves_is_printed_even_when_the_run_is_over_at_once(cli, plant: Path, tmp_path: Path) -> None:
    code, _, err = cli("run", plant, "--sim", "--duration", "0.05", "--no-status", "--state-dir", tmp_path,
                       "--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--modbus-port", "0")
    assert code == 0, err
    lines = err.splitlines()
    assert any(line.startswith("serving: OPC UA on opc.tcp://127.0.0.1:") for line in lines), err
    assert any(line.startswith("serving: Modbus TCP on 127.0.0.1:") for line in lines), err
    assert "press Ctrl-C to stop" in lines, err
    assert lines.index("press Ctrl-C to stop") < next(i for i, line in enumerate(lines) if line.startswith("stopped:"))


# -- which servers run: defaults, what is off, and --sim on free ports ------------------------


def test_without_a_servers_section_every_server_runs_on_loopback_default_ports(plant: Path) -> None:
    from softplc.app.adapters import build_adapters
    from softplc.app.cli import build_parser

    adapters = {a.name: a for a in build_adapters(load_config(plant), build_parser().parse_args(["run", str(plant)]))}
    assert set(adapters) == {"audit", "opcua", "modbus", "metrics", "hmi"}
    assert adapters["opcua"].settings.endpoint == "opc.tcp://127.0.0.1:4840/softplc/"
    assert (adapters["modbus"].settings.host, adapters["modbus"].settings.port) == ("127.0.0.1", 5020)
    assert (adapters["hmi"].settings.host, adapters["hmi"].settings.port) == ("127.0.0.1", 8080)


def test_run_says_which_servers_are_off_and_how_to_turn_them_on(cli, tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(PLANT + "servers:\n  opcua: {enabled: false}\n  modbus: {enabled: false}\n  hmi: {enabled: false}\n")
    code, _, err = cli("run", plant, "--sim", "--duration", "0.05", "--no-status", "--state-dir", tmp_path, "--no-audit")
    assert code == 0, err
    lines = err.splitlines()
    assert lines[1:5] == [
        "serving: nothing (no server enabled)",
        "not serving: OPC UA (servers.opcua.enabled: false in plant.yaml): set enabled: true to serve it",
        "not serving: Modbus TCP (servers.modbus.enabled: false in plant.yaml): set enabled: true, or give --modbus-port PORT, to serve it",
        "not serving: the web HMI (servers.hmi.enabled: false in plant.yaml): set enabled: true to serve it",
    ], err
    code, _, err = cli("run", plant, "--sim", "--duration", "0.05", "--no-status", "--state-dir", tmp_path, "--no-servers", "--modbus-port", "0")
    assert "not serving: OPC UA, Modbus TCP and the web HMI (--no-servers): run without it to serve them" in err.splitlines()
    code, _, err = cli("run", plant, "--sim", "--duration", "0.05", "--no-status", "--state-dir", tmp_path, "--modbus-port", "0")
    assert err.splitlines()[1].startswith("serving: audit trail: every client write and command to SQLite ")  # on by default
    assert [line for line in err.splitlines() if line.startswith(("serving:", "not serving:"))][2:] == [
        "not serving: OPC UA (servers.opcua.enabled: false in plant.yaml): set enabled: true to serve it",
        "not serving: the web HMI (servers.hmi.enabled: false in plant.yaml): set enabled: true to serve it"]


def test_under_sim_servers_bind_free_ports_unless_a_flag_says_otherwise(plant: Path) -> None:
    from softplc.app.adapters import build_adapters
    from softplc.app.cli import build_parser

    config, parser = load_config(plant), build_parser()

    def bound(*flags: str) -> tuple[str, int, int]:
        adapters = {a.name: a for a in build_adapters(config, parser.parse_args(["run", str(plant), *flags]))}
        return adapters["opcua"].settings.endpoint, adapters["modbus"].settings.port, adapters["hmi"].settings.port

    assert bound() == ("opc.tcp://127.0.0.1:4840/softplc/", 5020, 8080)  # real time: as configured
    assert bound("--sim") == ("opc.tcp://127.0.0.1:0/softplc/", 0, 0)
    assert bound("--sim", "--modbus-port", "1502", "--opcua-endpoint", "opc.tcp://127.0.0.1:4841/x/", "--hmi-port", "8181") == (
        "opc.tcp://127.0.0.1:4841/x/", 1502, 8181)
    off = plant.with_name("off.yaml")
    off.write_text(PLANT + "servers:\n  modbus: {enabled: false}\n")
    assert [a.name for a in build_adapters(load_config(off), parser.parse_args(["run", str(off), "--sim"]))] == ["audit", "opcua", "metrics", "hmi"]


def test_a_simulation_beside_a_running_plant_starts_and_serves(cli, tmp_path: Path) -> None:
    # The plant takes three ports; a simulation of a configuration naming exactly those ports must
    # not collide with it (before: "address already in use").
    (tmp_path / "plant.yaml").write_text(PLANT)
    running = Process(["run", str(tmp_path / "plant.yaml"), "--no-status", "--state-dir", str(tmp_path / "running"), *FREE_PORTS], tmp_path)
    try:
        running.wait_for("press Ctrl-C to stop", timeout=60)
        opcua_port = int(next(line for line in running.lines if line.startswith("serving: OPC UA on")).split(":")[3].split("/")[0])
        modbus_port = int(next(line for line in running.lines if line.startswith("serving: Modbus TCP on")).split()[4].split(":")[1])
        hmi_port = int(next(line for line in running.lines if line.startswith("serving: HMI on")).split(":")[3].split("/")[0])
        plant = tmp_path / "same_ports.yaml"
        plant.write_text(PLANT + f"servers:\n  opcua: {{endpoint: 'opc.tcp://127.0.0.1:{opcua_port}/softplc/'}}\n"
                         f"  modbus: {{port: {modbus_port}}}\n  hmi: {{port: {hmi_port}}}\n")
        code, _, err = cli("run", plant, "--sim", "--duration", "0.05", "--no-status", "--state-dir", tmp_path / "sim", "--no-audit")
        assert code == 0, err
        served = [line for line in err.splitlines() if line.startswith("serving: ") and not line.startswith("serving: metrics on")]
        assert len(served) == 3 and f":{opcua_port}/" not in served[0] and f":{modbus_port} " not in served[1], served
        assert served[0].startswith("serving: OPC UA on opc.tcp://127.0.0.1:") and served[1].startswith("serving: Modbus TCP on 127.0.0.1:")
        assert served[2].startswith("serving: HMI on http://127.0.0.1:") and f":{hmi_port}/" not in served[2], served
    finally:
        running.popen.send_signal(signal.SIGINT)
        running.finish(timeout=30)
        running.kill()
