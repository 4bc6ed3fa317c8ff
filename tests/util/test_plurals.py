"""Counts in what softplc prints and logs agree with their nouns: "1 tag", "2 tags", never "1 tags"."""

from __future__ import annotations

import asyncio
import logging
import re
import time
from pathlib import Path

import pytest
from conftest import REPO
from opcua_support import PASSWORDS, TEST_HASH_COST

from softplc.app.cli import main
from softplc.core.roles import Role
from softplc.security.users import UserStore
from softplc.util.peers import PeerLog
from softplc.util.plurals import counted, plural
from tests.app.test_cli import Process

CORE = REPO / "tests" / "core_programs.py"
ONE_OF_EACH = f"""
version: 1
tags:
  total: {{type: uint32}}
  flag: {{type: bool}}
tasks:
  t:
    interval: 100ms
    programs:
      - {{name: count, program: "{CORE}:Counter", bind: {{count: total}}}}
"""


def test_plural_and_counted() -> None:
    assert [plural(n, "tag") for n in (0, 1, 2)] == ["0 tags", "1 tag", "2 tags"]
    assert plural(1, "audit entry", "audit entries") == "1 audit entry" and plural(3, "audit entry", "audit entries") == "3 audit entries"
    assert counted(1, "more failed logins") == "1 more failed login"
    assert counted(1, "more connections closed for bad requests") == "1 more connection closed for bad requests"
    assert counted(4, "more failed logins") == "4 more failed logins"


def test_check_summary_says_1_task_and_1_program(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(ONE_OF_EACH.replace("  flag: {type: bool}\n", ""))
    assert main(["check", str(plant)]) == 0
    assert capsys.readouterr().out.strip() == f"{plant}: OK — 1 tag, 1 task (t 100ms), 1 program"


def test_serving_lines_count_in_the_singular(tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    # One bool tag over Modbus (the counter is left out), no _sys. tags there; one user.
    plant.write_text(ONE_OF_EACH.replace("total: {type: uint32}", "total: {type: uint32, modbus: {enabled: false}}")
                     + "servers:\n  modbus: {system_tags: false}\n")
    state = tmp_path / "state"
    state.mkdir()
    UserStore(state / "users.yaml").add("operator", Role.OPERATOR, PASSWORDS["operator"], log2_n=TEST_HASH_COST)
    process = Process(["run", str(plant), "--sim", "--duration", "1", "--no-status", "--state-dir", str(state), "--no-hmi"], tmp_path)
    try:
        code = process.finish(timeout=120)
    finally:
        process.kill()
    output = "\n".join(process.lines)
    assert code == 0, output
    assert "— 2 tags, 1 task (t 100ms), 1 program;" in output
    assert re.search(r"serving: OPC UA on .*; 1 user in ", output), output
    assert "(1 tag: 1 coil, 0 discrete inputs, 0 holding registers, 0 input registers;" in output, output


async def test_a_flood_summary_of_one_more_event_is_singular(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("softplc.test_plurals")
    peers = PeerLog(logger, interval=0.05, service="OPC UA")
    with caplog.at_level(logging.WARNING, logger=logger.name):
        peers.warning("10.0.0.9", "failed logins", "first")
        peers.warning("10.0.0.9", "failed logins", "second", detail="'alice'")
        deadline = time.monotonic() + 5
        while not any("more" in record.getMessage() for record in caplog.records):
            assert time.monotonic() < deadline, caplog.text
            await asyncio.sleep(0.01)
    assert [record.getMessage() for record in caplog.records] == [
        "first", "OPC UA: 1 more failed login from 10.0.0.9 in the last 0 s ('alice')"]
