"""The latency report: shares beside the thesis with their counts, security mode, labelled CSV rows."""

from __future__ import annotations

import asyncio
import csv
import io
import re
import sys

import pytest
from conftest import REPO

from softplc.latency.measurement import Measurement, Sample, Target
from softplc.latency.report import CSV_FIELDS, print_report, to_json, write_csv


def finished_run(delays: list[float], protocol: str = "opcua", security: str | None = None, label: str = "") -> Measurement:
    target = Target(protocol, "fast", scan=0.01, samples=len(delays), security=security)
    run = Measurement(target, label=label, endpoint="127.0.0.1:1", same_clock=True, client_exit=0, connected=True, ended="complete")
    run.warmup.append(Sample(0, 1, "start", 99.0, 99.001, 99.001, 99.002, None, None, 0))
    for index, delay in enumerate(delays, 1):
        t = 100.0 + index
        run.samples.append(Sample(index, index % 3 + 1, "ok", t, t + 0.001, t + 0.001, t + 0.002, delay, round(delay / 10), index))
    return run


def test_shares_have_counts_and_a_ratio_to_the_thesis():
    # 10, 10, 20 are ≤ 20 ms (3 of 4 = 75 %), 30 is in 20–40 (25 %), none above 40.
    data = to_json(finished_run([10.0, 10.0, 20.0, 30.0]))
    plc = data["plc"]
    assert (plc["count_le_20"], plc["count_20_40"], plc["count_gt_40"]) == (3, 1, 0)
    ratio = data["ratio_to_thesis"]
    assert ratio["share_le_20"] == pytest.approx(75.0 / 92)
    assert ratio["share_20_40"] == pytest.approx(25.0 / 5)
    assert ratio["share_gt_40"] == pytest.approx(0.0)
    text = io.StringIO()
    print_report([finished_run([10.0, 10.0, 20.0, 30.0])], text)
    row = next(line for line in text.getvalue().splitlines() if line.startswith("≤ 20 ms"))
    # thesis 92 % of its 1117 samples; ours 75 % of 4 (3 samples), 0.82 × the thesis's share.
    assert re.search(r"92 \(≈1028\)\s+75\.0 \(3\)\s+0\.82", row), row


@pytest.mark.parametrize("security, mode", [(None, "None"), ("SignAndEncrypt,/c.der,/k.pem", "SignAndEncrypt"), ("Sign", "Sign")])
def test_security_mode_in_json_and_table_header(security, mode):
    run = finished_run([10.0, 10.0], security=security)
    assert to_json(run)["security"] == mode
    text = io.StringIO()
    print_report([run], text)
    assert text.getvalue().splitlines()[0].endswith(f"OPC UA security {mode}")


def test_modbus_has_no_security_mode():
    run = finished_run([10.0], protocol="modbus")
    assert to_json(run)["security"] is None
    text = io.StringIO()
    print_report([run], text)
    assert "security" not in text.getvalue().splitlines()[0]


def test_csv_rows_say_which_run_they_belong_to(tmp_path):
    ours, naive = finished_run([10.0, 10.0]), finished_run([20.0, 30.0], label="naive 10ms")
    write_csv([ours, naive], tmp_path / "samples.csv")
    with (tmp_path / "samples.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [row["label"] for row in rows] == ["OPC UA sub 10ms"] * 3 + ["naive 10ms"] * 3
    assert {row["protocol"] for row in rows} == {"opcua"}  # the label is what tells them apart


def test_every_csv_column_is_documented():
    docs = (REPO / "docs" / "latency.md").read_text()
    for column in CSV_FIELDS:
        assert f"`{column}`" in docs, column


def test_report_says_what_was_requested_and_why_the_run_ended():
    run = finished_run([10.0] * 5)
    run.target.samples = 100
    run.client_exit, run.ended, run.missed = -9, "client died", 1
    run.errors.append("the client process was killed by signal 9")
    run.missed_notes.append("a Ready the PLC set 16.0 s after the client ended, never answered")
    text = io.StringIO()
    print_report([run], text)
    out = text.getvalue()
    assert "requested 100 samples · measured 5 · missed 1 · not attempted 94 · run ended: client died" in out
    assert "missed: a Ready the PLC set 16.0 s after the client ended, never answered" in out
    data = to_json(run)
    assert (data["not_attempted"], data["ended"], data["missed_notes"]) == (94, "client died", run.missed_notes)


async def test_baseline_bench_csv_tells_the_naive_rows_apart(tmp_path):
    process = await asyncio.create_subprocess_exec(
        sys.executable, str(REPO / "bench" / "latency_baseline.py"), "--scenario", "fast", "--samples", "3",
        "--protocols", "modbus", "--out", str(tmp_path), cwd=REPO,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )
    _, stderr = await asyncio.wait_for(process.communicate(), 120)
    assert (tmp_path / "samples.csv").exists(), stderr.decode()[-2000:]
    with (tmp_path / "samples.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert {row["label"] for row in rows} == {"Modbus 10ms", "naive 10ms"}
    assert sum(row["label"] == "naive 10ms" and row["kind"] == "sample" for row in rows) == 3
