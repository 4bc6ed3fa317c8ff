"""`softplc latency` for real: our runtime in real time, the client in its own process, over loopback."""

from __future__ import annotations

import asyncio
import io
import json
import os
import signal
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.core.clock import RealClock
from softplc.latency.measurement import Measurement, Target, measure
from softplc.latency.plant import handshake_config
from softplc.latency.progress import summary
from softplc.latency.report import to_json
from softplc.util.realtime import format_cpus

SAMPLES = 24


async def run_cli(*args: str, timeout: float = 120.0, env: dict[str, str] | None = None) -> tuple[int, str, str]:
    """Run `softplc ARGS` as a separate process; return (exit code, stdout, stderr)."""
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "softplc.app.cli", *args, cwd=REPO,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env={**os.environ, **(env or {})},
    )
    try:
        stdout, stderr = await asyncio.wait_for(process.communicate(), timeout)
    except TimeoutError:
        process.kill()
        await process.wait()
        raise
    return process.returncode or 0, stdout.decode(), stderr.decode()


def check_run(run: dict[str, Any], protocol: str, samples: int, *, hires: bool = True) -> None:
    """The JSON of one run has every field, and the values make sense for a 10 ms scan."""
    assert run["protocol"] == protocol and run["scenario"] == "fast" and run["scan_ms"] == 10.0
    assert run["complete"] is True and run["errors"] == []
    assert run["samples"] == samples and run["warmup"] == 1
    assert run["missed"] == 0 and run["timeouts"] == 0 and run["unreported"] == 0
    plc = run["plc"]
    for key in ("samples", "mean", "std", "mean_plus_std", "worst", "share_le_20", "share_20_40", "share_gt_40", "percentiles", "histogram"):
        assert key in plc, key
    assert plc["samples"] == samples
    # Quantised to the 10 ms scan: never below one scan, always a whole number of scans.
    assert 10.0 <= plc["mean"] <= plc["worst"]
    assert plc["best"] >= 10.0
    assert plc["share_le_20"] + plc["share_20_40"] + plc["share_gt_40"] == pytest.approx(100.0)
    assert set(plc["percentiles"]) == {"p50", "p95", "p99", "p999"}
    assert run["one_scan_percent"] is not None and 0 <= run["one_scan_percent"] <= 100
    assert run["thesis"]["mean"] == 15.8 and run["thesis"]["samples"] == 1117
    assert run["ratio_to_thesis"]["mean"] == pytest.approx(plc["mean"] / 15.8)
    if hires:
        high = run["hires"]
        # A sample whose ReadyStamp the PLC overwrote before the client read it has no hi-res delay
        # (a client held up past the next task: a busy machine); it is counted, never miscounted.
        assert high["samples"] == samples - run["stamps_lost"]
        # Ready → write acknowledged happens between the two scans that see it: 0 < hi-res < PLC delay + a scan.
        assert 0.0 < high["best"] and high["mean"] < plc["mean"] + 10.0
        # Ready → seen + seen → acknowledged = Ready → acknowledged, per sample; the means add up
        # when taken over the same samples (a sample with a lost stamp has no Ready → seen).
        assert run["notify"]["samples"] == high["samples"]
        if run["stamps_lost"] == 0:
            assert run["notify"]["mean"] + run["respond"]["mean"] == pytest.approx(high["mean"], rel=1e-6)
    else:
        assert run["hires"]["samples"] == 0
    assert run["respond"]["samples"] == samples and run["respond"]["best"] > 0.0


@pytest.mark.parametrize("protocol", ["opcua", "modbus"])
async def test_short_real_run_json(protocol, tmp_path):
    code, stdout, stderr = await run_cli("latency", "--protocol", protocol, "--scenario", "fast", "--samples", str(SAMPLES),
                                         "--json", "--out", str(tmp_path))
    assert code == 0, stderr
    data = json.loads(stdout)
    (run,) = data["runs"]
    check_run(run, protocol, SAMPLES)
    assert run["local_runtime"] is True and run["same_clock"] is True
    assert run["plc_task"]["program_state"] == "RUNNING"
    # The table went to stderr, beside the thesis's.
    assert "Mean (ms)" in stderr and "15.8" in stderr
    # --out: every sample in the CSV (plus the warm-up), the statistics, a figure.
    lines = (tmp_path / "samples.csv").read_text().splitlines()
    assert len(lines) == 1 + SAMPLES + 1
    assert json.loads((tmp_path / "statistics.json").read_text())["runs"][0]["samples"] == SAMPLES
    figure = tmp_path / f"latency-{protocol}-fast-10ms.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


async def test_killed_client_counts_the_missed_handshake():
    killed: list[int] = []

    def kill_after_five(run: Measurement) -> None:
        if len(run.samples) >= 5 and not killed and run.client_pid:
            os.kill(run.client_pid, signal.SIGKILL)
            killed.append(run.client_pid)

    result = await measure(Target("modbus", "fast", scan=0.01, samples=200), kill_after_five)
    assert killed
    assert len(result.samples) == 5
    assert result.client_exit == -signal.SIGKILL
    assert any("signal 9" in error for error in result.errors)
    # The PLC went on and set Ready; nobody answered it. An answer the client made but never
    # reported (killed in between) is counted too, never dropped.
    assert result.missed == 1
    assert result.unreported in (0, 1)
    data = to_json(result)
    assert data["complete"] is False and data["missed"] == 1 and data["samples"] == 5
    # With its context: when that Ready was set, what was never attempted, why the run ended.
    assert result.ended == "client died" and result.not_attempted == 200 - 5 - 1 - result.unreported
    (note,) = result.missed_notes
    assert "after the client ended" in note or "before the client ended" in note
    assert summary(result).startswith("samples 5 of 200 requested")


async def test_the_wait_after_the_client_died_is_announced_and_ends_at_ctrl_c():
    """Slow scenario: the warm-up answer starts task 1 (10 s); the client dies at once. The wait for
    the PLC's next Ready is announced, and stopping ends it: nothing is counted as missed."""
    stop = asyncio.Event()
    killed: list[int] = []
    announced: list[str] = []

    def progress(run: Measurement) -> None:
        if run.warmup and not killed and run.client_pid:
            os.kill(run.client_pid, signal.SIGKILL)
            killed.append(run.client_pid)
        if run.activity and not announced:
            announced.append(run.activity)
            stop.set()  # what Ctrl-C does

    result = await asyncio.wait_for(measure(Target("modbus", "slow", scan=0.01, samples=3), progress, stop), 60)
    assert killed and announced and "waiting up to 31 s for its next Ready" in announced[0]
    assert result.missed == 0 and not result.missed_notes  # the 10 s task was not waited out
    assert "interrupted by the user while waiting for the PLC's next Ready (not counted)" in result.errors
    assert result.ended == "client died" and result.not_attempted == 3


async def test_a_hung_client_ends_the_run_and_keeps_its_samples(monkeypatch):
    from softplc.latency import client_process

    monkeypatch.setattr(client_process, "WATCHDOG_MARGIN", 1.0)
    stopped: list[int] = []

    def freeze_after_three(run: Measurement) -> None:
        if len(run.samples) >= 3 and not stopped and run.client_pid:
            os.kill(run.client_pid, signal.SIGSTOP)
            stopped.append(run.client_pid)

    try:
        result = await asyncio.wait_for(measure(Target("modbus", "fast", scan=0.01, samples=200), freeze_after_three), 60)
    finally:
        for pid in stopped:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    assert stopped
    assert len(result.samples) == 3 and result.ended == "client hung"
    assert any("reported nothing for" in error and "it hangs and was killed" in error for error in result.errors)
    assert result.client_exit == -signal.SIGKILL and to_json(result)["samples"] == 3


async def _serve_handshake(tmp_path: Path, protocol: str) -> tuple[Runtime, str]:
    """A second runtime with the handshake plant, as a user would run it with `softplc run`."""
    from softplc.app.adapters import build_adapters

    if protocol == "opcua":
        from softplc.adapters.opcua import Role, UserStore

        UserStore(tmp_path / "users.yaml").add("tester", Role.OPERATOR, "handshake-test-password")
        config = handshake_config("fast", 0.01, opcua_endpoint="opc.tcp://127.0.0.1:0/softplc/")
    else:
        config = handshake_config("fast", 0.01, modbus_port=0)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    server: Any = next(adapter for adapter in runtime.adapters if adapter.name == protocol)
    return runtime, server.endpoint if protocol == "opcua" else f"127.0.0.1:{server.port}"


async def test_endpoint_opcua_against_a_second_runtime(tmp_path):
    """Signed and encrypted, logged in as an operator, with a client certificate the server trusts."""
    from softplc.adapters.opcua import Pki
    from softplc.latency.certificate import make_client_certificate

    certificate, key = make_client_certificate(tmp_path / "client")
    Pki(tmp_path / "pki").trust(str(certificate))
    runtime, endpoint = await _serve_handshake(tmp_path, "opcua")
    try:
        code, stdout, stderr = await run_cli("latency", "--endpoint", endpoint, "--samples", "12", "--json",
                                             "--security", f"SignAndEncrypt,{certificate},{key}",
                                             "--user", "tester", env={"SOFTPLC_LATENCY_PASSWORD": "handshake-test-password"})
        assert code == 0, stderr
        (run,) = json.loads(stdout)["runs"]
        check_run(run, "opcua", 12)
        assert run["local_runtime"] is False and run["endpoint"] == endpoint
        assert "security SignAndEncrypt" in run["driver"]
        # The PLC counted exactly the switches the client reported.
        assert runtime.db.value("Handshakes") >= 12
    finally:
        await runtime.stop()


async def test_endpoint_opcua_anonymous_is_refused_with_a_hint(tmp_path):
    """`softplc run programs/handshake.yaml` lets anonymous sessions only read: the error says how to log in."""
    runtime, endpoint = await _serve_handshake(tmp_path, "opcua")
    try:
        code, stdout, stderr = await run_cli("latency", "--endpoint", endpoint, "--samples", "3")
    finally:
        await runtime.stop()
    assert code == 1
    assert "BadUserAccessDenied" in stderr and "--user NAME" in stderr and "$SOFTPLC_LATENCY_PASSWORD" in stderr
    assert "softplc users add NAME --role operator" in stderr
    assert stderr.count("write refused") == 1  # the run's line; the report (stdout) has its own
    assert "after the client died" not in stderr + stdout


def test_the_documented_operator_login_lands_where_the_run_looks(tmp_path):
    """`softplc users add NAME --role operator --config programs/handshake.yaml` (as the docs say)
    writes the users file of the state directory `softplc run programs/handshake.yaml` uses."""
    import shutil
    import subprocess

    from softplc.adapters.opcua import UserStore
    from softplc.config import load_config

    for name in ("handshake.yaml", "handshake.py"):
        shutil.copy(REPO / "programs" / name, tmp_path / name)
    config = tmp_path / "handshake.yaml"
    docs = (REPO / "docs" / "latency.md").read_text() + (REPO / "programs" / "handshake.yaml").read_text()
    assert "softplc users add latency --role operator --config programs/handshake.yaml" in docs
    subprocess.run([sys.executable, "-m", "softplc.app.cli", "users", "add", "latency", "--role", "operator", "--config", str(config),
                    "--password-stdin"], input="handshake-password\n", text=True, check=True, capture_output=True, timeout=60)
    store = UserStore(load_config(config).state_dir / "users.yaml")
    assert "latency" in store


async def test_endpoint_modbus_third_party_layout(tmp_path):
    """A PLC exposing only Ready, TaskID and Delay (no counter, no stamp): PLC delays, no hi-res."""
    runtime, endpoint = await _serve_handshake(tmp_path, "modbus")
    try:
        code, stdout, stderr = await run_cli("latency", "--endpoint", endpoint, "--samples", "9", "--json",
                                             "--tag", "ready=holding:0", "--tag", "task_id=holding:1", "--tag", "delay=holding:7:float64",
                                             "--tag", "handshakes=", "--tag", "ready_stamp=", "--tag", "delay_scans=")
        assert code == 0, stderr
        (run,) = json.loads(stdout)["runs"]
        check_run(run, "modbus", 9, hires=False)
        assert run["driver"].startswith("Modbus TCP " + endpoint)
    finally:
        await runtime.stop()


async def test_bad_options_are_clear():
    code, _, stderr = await run_cli("latency", "--protocol", "modbus", "--client", "subscription")
    assert code == 1 and "Modbus has no subscriptions" in stderr
    code, _, stderr = await run_cli("latency", "--protocol", "opcua", "--endpoint", "127.0.0.1:502")
    assert code == 1 and "does not look like opcua" in stderr
    code, _, stderr = await run_cli("latency", "--endpoint", "127.0.0.1:1", "--samples", "3", "--tag", "ready=nowhere:1")
    assert code == 1 and "bad Modbus address 'nowhere:1'" in stderr
    code, stdout, stderr = await run_cli("latency", "--endpoint", "127.0.0.1:1", "--samples", "3")
    assert code == 1 and "cannot connect to Modbus TCP 127.0.0.1:1" in stderr
    # Said once; no table of nothing, no second read "after the client died" (it never connected).
    assert stderr.count("cannot connect") == 1 and "after the client died" not in stderr and stdout == ""


@pytest.mark.parametrize("endpoint", ["garbage", "http://x:1", "opc.tcp://"])
async def test_a_malformed_endpoint_starts_nothing(endpoint):
    code, stdout, stderr = await run_cli("latency", "--endpoint", endpoint, "--samples", "3")
    assert code == 1 and stdout == ""
    (line,) = stderr.strip().splitlines()  # one clear message, before any run
    assert line.startswith(f"softplc latency: --endpoint '{endpoint}'")


async def test_bad_numbers_exit_before_the_header():
    for option, value in (("--timeout", "-1"), ("--poll-interval", "-5"), ("--scan", "0.01")):
        code, stdout, stderr = await run_cli("latency", option, value)
        assert code == 2 and f"argument {option}:" in stderr and "run" not in stderr.splitlines()[-1].split(":")[0]
        assert "softplc latency: 1 run" not in stderr and stdout == ""


async def test_ctrl_c_at_start_ends_quietly():
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "softplc.app.cli", "latency", "--protocol", "modbus", "--samples", "50", cwd=REPO,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )
    assert process.stderr is not None
    header = await asyncio.wait_for(process.stderr.readline(), 60)
    assert header.startswith(b"softplc latency: 1 run")
    process.send_signal(signal.SIGINT)
    stdout, rest = await asyncio.wait_for(process.communicate(), 60)
    assert process.returncode == 1
    assert b"Traceback" not in rest and b"interrupted by the user" in rest



async def test_cpus_place_the_runtime_and_the_client_and_the_report_says_where():
    cpus = sorted(os.sched_getaffinity(0))
    runtime_cpu, client_cpu = cpus[0], cpus[-1]
    code, stdout, stderr = await run_cli("latency", "--protocol", "modbus", "--scenario", "fast", "--samples", "6", "--json",
                                         "--cpus", str(runtime_cpu), "--client-cpus", str(client_cpu))
    assert code == 0, stderr
    (run,) = json.loads(stdout)["runs"]
    check_run(run, "modbus", 6)
    assert run["conditions"]["runtime_cpus"] == str(runtime_cpu) and run["conditions"]["client_cpus"] == str(client_cpu)
    assert f"runtime on CPU {runtime_cpu} and client on CPU {client_cpu}" in stderr


async def test_cpus_that_cannot_be_had_are_refused_before_the_run():
    code, stdout, stderr = await run_cli("latency", "--samples", "3", "--client-cpus", "4096")
    assert code == 1 and stdout == ""
    machine = format_cpus(frozenset(range(os.cpu_count() or 1)))
    assert stderr.strip() == f"softplc latency: there is no CPU 4096: this machine has CPU {machine}"
    code, _, stderr = await run_cli("latency", "--endpoint", "127.0.0.1:1", "--samples", "3", "--cpus", "0")
    assert code == 1 and "--cpus places our runtime, which --endpoint does not start" in stderr
    code, _, stderr = await run_cli("latency", "--cpus", "zero")
    assert code == 2 and "argument --cpus: 'zero' is not a CPU list" in stderr


def test_the_client_refuses_a_cpu_it_cannot_be_kept_on(tmp_path):
    from softplc.latency import client

    out = io.StringIO()
    assert client.main(["--protocol", "modbus", "--endpoint", "127.0.0.1:1", "--cpus", "4096"], out=out) == 1
    (event,) = [json.loads(line) for line in out.getvalue().splitlines()]
    assert event["type"] == "error" and event["message"].startswith("--cpus: there is no CPU 4096")
