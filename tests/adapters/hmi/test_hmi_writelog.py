"""The HMI's write log: every write through the HMI, accepted or refused, with its user; a flood is summarised."""

from __future__ import annotations

import asyncio
import logging

import pytest

from softplc.adapters.hmi.writelog import WriteLog
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, WriteEvent

pytestmark = pytest.mark.asyncio

ALICE = Origin("hmi", "alice", "127.0.0.1", Role.OPERATOR)


async def test_each_write_is_logged_with_its_user_and_a_flood_becomes_one_summary(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="softplc.adapters.hmi")
    log = WriteLog(interval=0.2, burst=3)
    log([WriteEvent(1.0, ALICE, "t01_iFr", 30.0, 20.0)])
    log([WriteEvent(1.0, ALICE, "limit", 5.0, 1000.0, Rule.OUT_OF_RANGE, "1000.0 is above the maximum 100")])
    log([WriteEvent(1.0, Origin("modbus"), "limit", 5.0, 6.0)])  # not the HMI's: the HMI does not log it
    for value in range(20):
        log([WriteEvent(1.0, ALICE, "limit", 5.0, float(value))])
    lines = [record.getMessage() for record in caplog.records]
    assert lines[0] == "HMI write by hmi:alice@127.0.0.1 (operator): t01_iFr = 20.0 (was 30.0)"
    assert lines[1] == "HMI write by hmi:alice@127.0.0.1 (operator) refused: limit = 1000.0: out of range: 1000.0 is above the maximum 100"
    assert len(lines) == 3  # the burst: then quiet
    await asyncio.sleep(0.35)
    lines = [record.getMessage() for record in caplog.records]
    assert lines[-1] == "HMI: 19 more writes by hmi:alice@127.0.0.1 in the last 0.2 s (0 refused; tags limit)"
