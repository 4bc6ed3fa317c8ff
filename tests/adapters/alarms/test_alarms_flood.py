"""An alarm flood is flagged (ISA-18.2: more than 10 alarms within 10 minutes, over when fewer than 5), on the simulated clock."""

from __future__ import annotations

import logging

from tests.alarms_support import EPOCH, call, plant, simulate, write

TEMPLATE_HEAD = """
version: 1
templates:
  valve:
    instances: [v01, v02, v03, v04, v05, v06, v07, v08, v09, v10, v11, v12]
    tags:
      fault: {type: bool}
tags:
  spare: {type: bool}
tasks:
  scan:
    interval: 100ms
"""
ALARMS = """
definitions:
  - {name: "{valve}_fault", for_each: valve, discrete: {tag: "{valve}_fault", value: true}}
  - {name: spare_on, discrete: {tag: spare, value: true}}
"""


def _valves(at: float, count: int, value: bool) -> list:
    return [write(at, f"v{index:02d}_fault", value) for index in range(1, count + 1)]


async def test_more_than_ten_alarms_in_ten_minutes_is_a_flood_until_fewer_than_five(tmp_path, caplog) -> None:
    caplog.set_level(logging.INFO, logger="softplc.adapters.alarms.engine")
    steps = [
        *_valves(10.05, 10, True), call(20.0, "alarms.summary", role="viewer"),  # ten: not yet a flood
        write(30.05, "v11_fault", True), call(40.0, "alarms.summary", role="viewer"),  # the eleventh
        *_valves(50.05, 11, False), call(60.0, "alarms.shelve", alarm="spare_on", reason="test", duration="1h"),
        write(70.05, "spare", True),  # shelved: not shown to the operator, not counted
        call(600.0, "alarms.summary", role="viewer"),  # the first ten leave the window at 610 s (10 s steps)
        call(615.0, "alarms.summary", role="viewer"),
    ]
    run = await simulate(tmp_path, plant(ALARMS, head=TEMPLATE_HEAD), steps, 620)
    summaries = [(at, result["rate"], result["flood"], result["flood_since"]) for at, command, result in run.results
                 if command == "alarms.summary"]
    assert summaries == [(20.0, 10, False, None), (40.0, 11, True, EPOCH + 30.1), (600.0, 11, True, EPOCH + 30.1),
                         (615.0, 1, False, None)]
    db = run.runtime.db
    assert db.value("_sys.alarms.flood") is False and db.value("_sys.alarms.rate") == 1
    lines = [record.getMessage() for record in caplog.records if "flood" in record.getMessage()]
    assert len(lines) == 2 and lines[0].startswith("alarm flood: 11 alarms annunciated within 10 minutes")
    assert lines[1] == "alarm flood over: 1 alarm annunciated within 10 minutes"


async def test_the_flood_tag_follows_the_flood(tmp_path) -> None:
    steps = [*_valves(1.05, 12, True), call(2.0, "alarms.summary", role="viewer")]
    run = await simulate(tmp_path, plant(ALARMS, head=TEMPLATE_HEAD), steps, 3)
    assert run.results[-1][2]["flood"] is True
    db = run.runtime.db
    assert db.value("_sys.alarms.flood") is True and db.value("_sys.alarms.rate") == 12
