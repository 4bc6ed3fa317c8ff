"""The alarm journal on SQLite and on a real PostgreSQL server: every transition and action, searchable, CSV."""

from __future__ import annotations

import asyncio
import csv
import io
from pathlib import Path

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.storage import BatchWriter, Database, StorageSettings
from softplc.storage.alarm_journal import AlarmJournal, JournalQuery, JournalSink, search, write_csv
from tests.alarms_support import DRIVER, EPOCH, PEOPLE, call, plant, simulate, write

ALARMS = """
definitions:
  - {name: level_hi, limit: {tag: level, hi: 90}, priority: high, message: "level {value:.0f} m"}
  - {name: nav_failed, discrete: {tag: navstate, value: failed}, message: "robot navigation failed"}
"""
STEPS = [
    write(1.05, "level", 95), call(2.05, "alarms.acknowledge", alarm="level_hi", comment="checking the pump"),
    write(3.05, "navstate", "failed"), call(4.05, "alarms.shelve", alarm="nav_failed", reason="robot in repair", duration="1h"),
    write(5.05, "level", 10), call(6.05, "alarms.comment", role="engineer", alarm="nav_failed", comment="new wheel ordered"),
]


def _journal(settings: StorageSettings, plant_name: str, retention: float | None = None, now: float = 0.0) -> AlarmJournal:
    database = Database(settings)
    writer = BatchWriter(database, name="test-journal")
    writer.register(JournalSink(retention, lambda: now))
    assert writer.start() is None
    return AlarmJournal(database, writer, plant_name)


async def test_every_transition_and_action_is_journaled_searchable_and_exported(storage_settings, tmp_path: Path) -> None:
    run = await simulate(tmp_path, plant(ALARMS), STEPS, 8)
    journal = _journal(storage_settings, "alarm-test")
    other = AlarmJournal(journal.database, journal.writer, "other-plant")  # a second runtime sharing the store
    try:
        for event in run.events:
            journal.record(event)
            other.record(event)
        assert journal.flush()
        rows = journal.search(JournalQuery())
        assert [(round(row.time - EPOCH, 2), row.alarm, row.transition, row.state, row.user) for row in rows] == [
            (6.05, "nav_failed", "commented", "shelved", "engineer"),
            (5.1, "level_hi", "cleared", "normal", ""),
            (4.05, "nav_failed", "shelved", "shelved", "operator"),
            (3.1, "nav_failed", "activated", "unacknowledged", ""),
            (2.05, "level_hi", "acknowledged", "acknowledged", "operator"),
            (1.1, "level_hi", "activated", "unacknowledged", ""),
        ]
        acknowledged = rows[4]
        assert (acknowledged.comment, acknowledged.role, acknowledged.priority, acknowledged.severity) == ("checking the pump", "operator", "high", 700)
        assert acknowledged.message == "level 95 m" and acknowledged.value == "95.0" and acknowledged.previous == "unacknowledged"
        assert rows[2].comment == "robot in repair"
        assert [row.transition for row in journal.search(JournalQuery(alarm="nav_*"))] == ["commented", "shelved", "activated"]
        assert [row.transition for row in journal.search(JournalQuery(text="PUMP"))] == ["acknowledged"]
        assert [row.transition for row in journal.search(JournalQuery(user="engineer"))] == ["commented"]
        assert [row.alarm for row in journal.search(JournalQuery(transitions=("activated",)))] == ["nav_failed", "level_hi"]
        assert [row.transition for row in journal.search(JournalQuery(since=EPOCH + 2, until=EPOCH + 4))] == ["activated", "acknowledged"]
        assert [row.transition for row in journal.search(JournalQuery(limit=2, offset=1))] == ["cleared", "shelved"]
        assert len(journal.search(JournalQuery(plant="*"))) == 12
        assert {row.plant for row in other.search(JournalQuery())} == {"other-plant"}
        stream = io.StringIO()
        assert write_csv(rows, stream) == 6
        table = list(csv.DictReader(io.StringIO(stream.getvalue())))
        assert table[-1]["time_utc"] == "2026-01-01T00:00:01.100Z" and table[-1]["alarm"] == "level_hi"
        assert table[1]["transition"] == "cleared" and set(table[0]) >= {"user", "comment", "message", "plant"}
    finally:
        journal.writer.stop()


async def test_retention_drops_old_rows(storage_settings, tmp_path: Path) -> None:
    run = await simulate(tmp_path, plant(ALARMS), STEPS, 8)
    journal = _journal(storage_settings, "alarm-test", retention=3.0, now=EPOCH + 6.0)
    try:
        for event in run.events:
            journal.record(event)
        assert journal.writer.flush(maintain=True)
        assert [round(row.time - EPOCH, 2) for row in journal.search(JournalQuery())] == [6.05, 5.1, 4.05, 3.1]
    finally:
        journal.writer.stop()


async def test_a_running_plant_journals_to_its_configured_backend(storage_settings, tmp_path: Path) -> None:
    if storage_settings.backend == "sqlite":
        section = f'journal: {{path: "{storage_settings.path}", flush_period: 50ms}}'
    else:
        section = f'journal: {{backend: postgresql, dsn: "{storage_settings.dsn}", flush_period: 50ms}}'
    path = tmp_path / "tagdb.yaml"
    path.write_text(plant(section + "\ndefinitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}}"))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    for adapter in build_adapters(config, None):
        if adapter.name == "alarms":
            runtime.add_adapter(adapter)
    await runtime.start()
    try:
        runtime.db.submit([("level", 95.0)], DRIVER)
        for _ in range(200):
            if runtime.db.value("_sys.alarms.unacknowledged") == 1:
                break
            await asyncio.sleep(0.01)
        assert await runtime.commands.call("alarms.acknowledge", {"alarm": "level_hi"}, PEOPLE["operator"]) == "acknowledged level_hi (now acknowledged)"
        rows = await runtime.commands.call("alarms.journal", {"alarm": "level_hi"}, PEOPLE["viewer"])
        assert [(row["transition"], row["user"], row["plant"]) for row in rows] == [("acknowledged", "operator", "alarm-test"), ("activated", "", "alarm-test")]
    finally:
        await runtime.stop()
    # Committed: a reader that is not the runtime finds the rows.
    assert len(search(Database(storage_settings), JournalQuery(), "alarm-test")) == 2


async def test_alarms_keep_working_while_the_journal_store_is_down_and_say_so(tmp_path: Path, caplog) -> None:
    import socket

    from softplc.core.commands import CommandRefused

    with socket.socket() as probe:  # a loopback port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    path = tmp_path / "tagdb.yaml"
    section = f'journal: {{backend: postgresql, dsn: "host=127.0.0.1 port={port} dbname=plant user=softplc connect_timeout=2"}}'
    path.write_text(plant(section + "\ndefinitions:\n  - {name: level_hi, limit: {tag: level, hi: 90}}"))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    for adapter in build_adapters(config, None):
        if adapter.name == "alarms":
            runtime.add_adapter(adapter)
    await runtime.start()
    try:
        assert "alarm journal: cannot open PostgreSQL" in caplog.text
        runtime.db.submit([("level", 95.0)], DRIVER)
        for _ in range(200):
            if runtime.db.value("_sys.alarms.unacknowledged") == 1:
                break
            await asyncio.sleep(0.01)
        assert await runtime.commands.call("alarms.acknowledge", {"alarm": "level_hi"}, PEOPLE["operator"]) == "acknowledged level_hi (now acknowledged)"
        try:
            await runtime.commands.call("alarms.journal", {}, PEOPLE["viewer"])
        except CommandRefused as refused:
            assert str(refused).startswith("the alarm journal cannot be read now:")
        else:
            raise AssertionError("the journal read did not fail")
        adapter = next(adapter for adapter in runtime.adapters if adapter.name == "alarms")
        assert adapter.journal.writer.stats.pending == 2  # kept for when the store is back
    finally:
        await runtime.stop()
