"""A pair on one shared PostgreSQL (the documented setup): history, alarm journal and audit written once, across a failover.

Two members in one process on the real clock, a real etcd and a real PostgreSQL: the standby
records nothing (not even when it stops), a write acknowledged by the old active is in the audit
trail once, the takeover journals no alarm transition again, and the history goes on after the
failover without a doubled sample — and without leaving an unchanged tag BAD from the old
active's end of recording.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

from softplc.adapters.history.queries import HistoryReader
from softplc.app.runtime import Runtime
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality
from softplc.storage import Database, StorageSettings
from softplc.storage.alarm_journal import JournalQuery
from softplc.storage.alarm_journal import search as journal_search
from softplc.storage.audit.queries import AuditQuery
from softplc.storage.audit.queries import search as audit_search
from tests.adapters.redundancy.pair_support import write_pair
from tests.adapters.redundancy.test_pair_inprocess import member, role, until

OPERATOR = Origin("hmi", "olga", "127.0.0.1", role=Role.OPERATOR)

STORAGE = """
history:
  backend: postgresql
  dsn: "{dsn}"
  flush_period: 50ms
  record:
    - {{tags: [scans, spare, setpoint]}}
audit: {{backend: postgresql, dsn: "{dsn}", flush_period: 50ms}}
alarms:
  journal: {{backend: postgresql, dsn: "{dsn}", flush_period: 50ms}}
  definitions:
    - {{name: spare_high, limit: {{tag: spare, hi: 100}}, priority: high}}
"""


async def settle(runtime: Runtime, value: int) -> None:
    assert runtime.db.submit([("spare", value)], OPERATOR) == [None]
    await until(lambda: runtime.db.value("spare") == value, 2, f"spare = {value} applied")


async def spare_high(runtime: Runtime) -> str:
    """The state of the alarm spare_high as `alarms.list` shows it (the HMI's and OPC UA's view)."""
    (listed,) = await runtime.commands.call("alarms.list", {"name": "spare_high"}, OPERATOR)
    return str(listed["state"])


async def until_state(runtime: Runtime, state: str, what: str) -> None:
    deadline = time.monotonic() + 2.0
    while await spare_high(runtime) != state:
        assert time.monotonic() < deadline, f"not within 2 s: {what}"
        await asyncio.sleep(0.01)


async def test_history_alarm_journal_and_audit_are_written_once_across_a_failover(tmp_path: Path, etcd: Any, postgres_dsn: str) -> None:
    path = write_pair(tmp_path, etcd.endpoint, extra=STORAGE.format(dsn=postgres_dsn.replace('"', '\\"')))
    a, b = member(path, "a", tmp_path), member(path, "b", tmp_path)
    began = time.time()
    await asyncio.gather(a.start(), b.start())
    runtimes = [a, b]
    try:
        await until(lambda: role(a) == "ACTIVE" and b.db.value("_sys.redundancy.peer_ok"), 10, "a active and b in sync")
        assert a.db.submit([("setpoint", 2.5)], OPERATOR) == [None]
        for value in (1, 2, 150):
            await settle(a, value)
        await until_state(a, "unacknowledged", "spare_high annunciated")
        await a.commands.call("alarms.acknowledge", {"alarm": "spare_high", "comment": "seen"}, OPERATOR)
        await until_state(b, "acknowledged", "b mirrors the acknowledgement")

        # The standby restarts (maintenance) while the active records: it writes nothing, not even an end of recording.
        await b.stop()
        b = member(path, "b", tmp_path)
        runtimes[1] = b
        await b.start()
        await until(lambda: b.db.value("_sys.redundancy.peer_ok") and b.db.value("spare") == 150, 10, "b in sync again")
        # its first full state carried the alarms' part: b took it (its alarms adapter had started), not refused it
        assert a.db.value("_sys.redundancy.refused") == 0 and b.db.value("_sys.redundancy.refused") == 0
        await settle(a, 120)  # still high: spare_high stays active and acknowledged
        await until(lambda: b.db.value("spare") == 120, 2, "b mirrors spare")

        await a.stop()  # a clean stop: b takes over at once
        stopped = time.time()
        await until(lambda: role(b) == "ACTIVE", 3, "b active")
        for value in (3, 4, 5):  # 3 clears spare_high, on b
            await settle(b, value)
        await asyncio.sleep(0.3)  # b records scans for a while
        finishing = time.time()  # b's own stop then ends its recording (BAD samples at that time): not looked at
        await b.stop()
        ended = time.time()
    finally:
        for runtime in runtimes:
            await runtime.stop()

    settings = StorageSettings.postgresql(postgres_dsn)
    database = Database(settings)
    writes = [(entry.tag, entry.new) for entry in reversed(audit_search(database, AuditQuery(kind="write", tag="spare"), "pairtest"))]
    assert writes == [("spare", value) for value in (1, 2, 150, 120, 3, 4, 5)]  # each once, whoever was active
    commands = audit_search(database, AuditQuery(command="alarms.acknowledge"), "pairtest")
    assert len(commands) == 1
    everything = list(reversed(journal_search(database, JournalQuery(), "pairtest")))
    journal = [(row.alarm, row.transition, row.state) for row in everything if row.alarm == "spare_high"]
    # activated and acknowledged on a; b took it over acknowledged: cleared (not activated again)
    assert journal == [("spare_high", "activated", "unacknowledged"), ("spare_high", "acknowledged", "acknowledged"),
                       ("spare_high", "cleared", "normal")]

    reader = HistoryReader(database, "pairtest")
    try:
        scans = reader.raw("scans", 0.0, ended + 10).samples
        times = [sample.time for sample in scans]
        assert len(times) == len(set(times)), "a sample of scans stored twice"
        good = [sample for sample in scans if sample.quality is Quality.GOOD]
        assert [sample.value for sample in good] == sorted(sample.value for sample in good)  # one counter, never two interleaved
        # the standby's stop while a recorded left no end-of-recording sample
        assert not [sample for sample in scans if sample.quality is Quality.BAD and began < sample.time < stopped - 0.5]
        # setpoint did not change after the failover: it is not left BAD by the old active's end of recording
        setpoint = reader.raw("setpoint", 0.0, finishing).samples
        assert setpoint[-1].quality is Quality.GOOD and setpoint[-1].value == 2.5 and setpoint[-1].time >= stopped - 0.5
    finally:
        reader.close()
