"""The audit store on SQLite and on a real PostgreSQL server: entries kept as given, found by every filter, retention by partition."""

from __future__ import annotations

import csv
import io
from typing import Any

from softplc.core.commands import CommandCall
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, WriteEvent
from softplc.storage import BatchWriter, Database, StorageSettings
from softplc.storage.audit.entry import MAX_REFUSED, CallRecord
from softplc.storage.audit.queries import AuditQuery, search, write_csv
from softplc.storage.audit.store import CATALOGUE, AuditSink

DAY = 86400.0
T0 = 1_767_225_600.0  # 2026-01-01T00:00:00Z
ALICE = Origin("opcua", "alice", "10.0.0.7:51022", Role.OPERATOR)
BOB = Origin("hmi", "bob", "10.0.0.9:40001", Role.ENGINEER)
MODBUS = Origin("modbus", "", "10.0.0.8:502", Role.OPERATOR)


def items() -> list[Any]:
    """Two days of a plant's audit: writes and commands from three clients."""
    return [
        WriteEvent(T0 + 10, ALICE, "t01_iFr", 30.0, 45.0),
        WriteEvent(T0 + 20, ALICE, "t01_iFr", 45.0, 700.0, Rule.OUT_OF_RANGE, "700.0 is above the maximum 600"),
        WriteEvent(T0 + 30, MODBUS, "t02_iFr", 10, 12),
        WriteEvent(T0 + 40, MODBUS, "name", "idle", "Grüße \u2013 \"quoted\""),
        CallRecord(CommandCall(T0 + 50, BOB, "tags.force", {"tag": "t01_iFr", "value": "0"}, True, "t01_iFr forced to 0.0"), "t01_iFr", 45.0, 0.0, ""),
        CallRecord(CommandCall(T0 + 60, ALICE, "tags.force", {"tag": "t02_iFr", "value": "1"}, False, "role operator may not force tags"),
                   "t02_iFr", 12, 1.0, "access denied"),
        CallRecord(CommandCall(T0 + DAY + 5, ALICE, "alarms.acknowledge", {"alarm": "t01_full", "comment": "ok"}, True, "acknowledged"), "", None, None, ""),
        WriteEvent(T0 + DAY + 10, ALICE, "flag", None, [1, 2], Rule.TYPE_MISMATCH, "expected bool"),
        WriteEvent(T0 + DAY + 20, MODBUS, "t01_iFr", 0.0, 50.0, Rule.FORCED, "the tag is forced; unforce it first"),
    ]


def store(settings: StorageSettings, plant: str = "plant-a", *, retention: float | None = None, now: float = T0) -> tuple[Database, BatchWriter]:
    database = Database(settings)
    writer = BatchWriter(database, name="test-audit")
    writer.register(AuditSink(plant, partition=DAY, retention=retention, now=lambda: now))
    assert writer.start() is None
    return database, writer


def names(database: Database, query: AuditQuery, plant: str = "plant-a") -> list[str]:
    return [f"{entry.name}@{entry.time - T0:g}" for entry in search(database, query, plant)]


def test_entries_keep_who_what_old_new_and_rule_as_given(storage_settings) -> None:
    database, writer = store(storage_settings)
    try:
        writer.put("audit", items())
        assert writer.flush()
        found = list(reversed(search(database, AuditQuery(), "plant-a")))
    finally:
        writer.stop()
    assert [(e.kind, e.source, e.user, e.peer, e.role, e.name, e.tag, e.old, e.new, e.accepted, e.rule) for e in found] == [
        ("write", "opcua", "alice", "10.0.0.7:51022", "operator", "t01_iFr", "t01_iFr", 30.0, 45.0, True, ""),
        ("write", "opcua", "alice", "10.0.0.7:51022", "operator", "t01_iFr", "t01_iFr", 45.0, 700.0, False, "out of range"),
        ("write", "modbus", "", "10.0.0.8:502", "operator", "t02_iFr", "t02_iFr", 10, 12, True, ""),
        ("write", "modbus", "", "10.0.0.8:502", "operator", "name", "name", "idle", "Grüße \u2013 \"quoted\"", True, ""),
        ("command", "hmi", "bob", "10.0.0.9:40001", "engineer", "tags.force", "t01_iFr", 45.0, 0.0, True, ""),
        ("command", "opcua", "alice", "10.0.0.7:51022", "operator", "tags.force", "t02_iFr", 12, 1.0, False, "access denied"),
        ("command", "opcua", "alice", "10.0.0.7:51022", "operator", "alarms.acknowledge", "", None, None, True, ""),
        ("write", "opcua", "alice", "10.0.0.7:51022", "operator", "flag", "flag", None, [1, 2], False, "type mismatch"),
        ("write", "modbus", "", "10.0.0.8:502", "operator", "t01_iFr", "t01_iFr", 0.0, 50.0, False, "forced"),
    ]
    assert [type(e.old) for e in found[:3]] == [float, float, int]  # types survive the store
    assert found[1].detail == "700.0 is above the maximum 600" and found[4].detail == "t01_iFr forced to 0.0"
    assert found[4].arguments == {"tag": "t01_iFr", "value": "0"} and found[0].arguments is None
    assert found[0].time == T0 + 10 and found[0].plant == "plant-a"


def test_every_filter(storage_settings) -> None:
    database, writer = store(storage_settings)
    other = AuditSink("plant-b", partition=DAY, retention=None, now=lambda: T0)  # a second runtime sharing the store
    try:
        writer.put("audit", items())
        assert writer.flush()
        connection = database.connect()
        try:
            other.prepare(connection, database)
            other.write(connection, database, items()[:2])
            connection.commit()
        finally:
            connection.close()
    finally:
        writer.stop()
    assert names(database, AuditQuery()) == ["t01_iFr@86420", "flag@86410", "alarms.acknowledge@86405", "tags.force@60", "tags.force@50",
                                             "name@40", "t02_iFr@30", "t01_iFr@20", "t01_iFr@10"]
    assert names(database, AuditQuery(since=T0 + 30, until=T0 + DAY + 10)) == ["alarms.acknowledge@86405", "tags.force@60", "tags.force@50", "name@40", "t02_iFr@30"]
    # a tag: its writes and the commands acting on it (the force); a pattern, case-sensitive like tag names
    assert names(database, AuditQuery(tag="t01_iFr")) == ["t01_iFr@86420", "tags.force@50", "t01_iFr@20", "t01_iFr@10"]
    assert names(database, AuditQuery(tag="t0?_*", kind="write")) == ["t01_iFr@86420", "t02_iFr@30", "t01_iFr@20", "t01_iFr@10"]
    assert names(database, AuditQuery(tag="T01_*")) == []
    assert names(database, AuditQuery(command="tags.*")) == ["tags.force@60", "tags.force@50"]
    assert names(database, AuditQuery(command="alarms.acknowledge", tag="name")) == ["alarms.acknowledge@86405", "name@40"]
    assert names(database, AuditQuery(user="bob")) == ["tags.force@50"]
    assert names(database, AuditQuery(source="MODBUS")) == ["t01_iFr@86420", "name@40", "t02_iFr@30"]
    assert names(database, AuditQuery(source="op*", accepted=True)) == ["alarms.acknowledge@86405", "t01_iFr@10"]
    assert names(database, AuditQuery(peer="10.0.0.9:*")) == ["tags.force@50"]
    assert names(database, AuditQuery(accepted=False)) == ["t01_iFr@86420", "flag@86410", "tags.force@60", "t01_iFr@20"]
    assert names(database, AuditQuery(kind="command")) == ["alarms.acknowledge@86405", "tags.force@60", "tags.force@50"]
    assert names(database, AuditQuery(limit=3, offset=2)) == ["alarms.acknowledge@86405", "tags.force@60", "tags.force@50"]
    assert names(database, AuditQuery(limit=2, offset=8)) == ["t01_iFr@10"]
    assert names(database, AuditQuery(tag="t_%\\")) == []  # LIKE's own wildcards are literal characters here
    # plants: this one's by default, another's by name, every plant's with *
    assert names(database, AuditQuery(plant="plant-b")) == ["t01_iFr@20", "t01_iFr@10"]
    assert len(search(database, AuditQuery(plant="*"), "plant-a")) == 11


def test_a_huge_value_is_clipped_and_an_odd_one_kept_as_text(storage_settings) -> None:
    database, writer = store(storage_settings)
    try:
        writer.put("audit", [WriteEvent(T0, ALICE, "name", "", "x" * 100_000, Rule.OUT_OF_RANGE, "d" * 10_000),
                             WriteEvent(T0 + 1, ALICE, "name", "", b"\x00\xff", Rule.TYPE_MISMATCH, "bytes"),
                             WriteEvent(T0 + 2, ALICE, "level", 1.0, float("nan"), Rule.OUT_OF_RANGE, "NaN")])
        assert writer.flush()
        huge, odd, nan = reversed(search(database, AuditQuery(), "plant-a"))
    finally:
        writer.stop()
    assert huge.new.startswith('"xxxx') and huge.new.endswith("… (100002 characters)") and len(huge.new) < MAX_REFUSED + 40
    assert huge.detail.endswith("… (10000 characters)") and len(huge.detail) < MAX_REFUSED + 40  # a refused entry: clipped shorter
    assert odd.new == "b'\\x00\\xff'"
    assert nan.new != nan.new  # NaN stays NaN


def test_retention_drops_whole_partitions(storage_settings) -> None:
    now = T0 + 3 * DAY + 100
    database, writer = store(storage_settings, retention=2 * DAY, now=now)
    try:
        writer.put("audit", [WriteEvent(T0 + day * DAY + 1, ALICE, f"day{day}", 0, 1) for day in range(4)])
        assert writer.flush(maintain=True)
        connection = database.connect(readonly=True)
        try:
            partitions = [name for (name,) in connection.execute(f"SELECT name FROM {CATALOGUE} ORDER BY start").fetchall()]
        finally:
            connection.close()
        assert names(database, AuditQuery()) == ["day3@259201", "day2@172801", "day1@86401"]
    finally:
        writer.stop()
    # 2026-01-01 ended before now - 2 days: its table is dropped, not emptied row by row; 2026-01-02
    # ends after it and is kept whole (an entry is dropped at most one partition after its time).
    assert partitions == ["audit_20260102_000000", "audit_20260103_000000", "audit_20260104_000000"]


def test_csv_has_a_header_and_values_as_people_read_them(storage_settings) -> None:
    database, writer = store(storage_settings)
    try:
        writer.put("audit", items())
        assert writer.flush()
        rows = search(database, AuditQuery(user="bob"), "plant-a") + search(database, AuditQuery(tag="name"), "plant-a")
    finally:
        writer.stop()
    stream = io.StringIO()
    assert write_csv(rows, stream) == 2
    table = list(csv.DictReader(io.StringIO(stream.getvalue())))
    assert table[0]["time_utc"] == "2026-01-01T00:00:50.000Z" and table[0]["name"] == "tags.force" and table[0]["new"] == "0.0"
    assert table[0]["arguments"] == '{"tag": "t01_iFr", "value": "0"}' and table[0]["accepted"] == "True"
    assert table[1]["old"] == "idle" and table[1]["new"] == 'Grüße – "quoted"'


def test_an_empty_or_missing_store_has_no_entries(tmp_path) -> None:
    database = Database(StorageSettings.sqlite(tmp_path / "audit.sqlite"))
    connection = database.connect()  # the file exists, without any table
    connection.close()
    assert search(database, AuditQuery(), "plant-a") == []
