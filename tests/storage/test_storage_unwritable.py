"""A row a store cannot take never stops it: text stored escaped, the rest set aside and reported (issue 21, item 1).

Invalid UTF-8 received over OPC UA (bytes ff fe) reaches Python as lone surrogates, which
neither SQLite nor PostgreSQL can encode; a NUL is refused by PostgreSQL's text; a number too
large for an integer column is refused by both. The shared writer escapes the text and sets
aside what still cannot be written, on both backends, for the history, the audit trail and the
alarm journal alike; rows queued behind a poisoned one are written at the same flush.
"""

from __future__ import annotations

import logging
from dataclasses import astuple
from pathlib import Path
from typing import Any

from asyncua import ua

from softplc.adapters.history.queries import HistoryReader
from softplc.adapters.history.store import SINK_NAME, HistorySink, TagInfo
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, WriteEvent
from softplc.core.tags import Quality
from softplc.storage import BatchWriter, Database, StorageSettings
from softplc.storage.alarm_journal import TABLE, AlarmJournal, JournalEntry, JournalQuery, JournalSink
from softplc.storage.audit.queries import AuditQuery, search
from softplc.storage.audit.store import AuditSink
from softplc.storage.unwritable import escape_text, escaped
from tests.audit_support import entries, opcua_client, running, wait_until

T0 = 1_767_225_600.0
ALICE = Origin("opcua", "alice", "127.0.0.1:50000", Role.OPERATOR)
NOT_UTF8 = b"\xff\xfe".decode("utf-8", "surrogateescape")  # what asyncua makes of the bytes ff fe in a String


def journal_entry(number: int, message: str = "level high", severity: int = 700) -> tuple[Any, ...]:
    """A journal row as the journal hands it to the writer (a tuple in JournalEntry's field order)."""
    return astuple(JournalEntry(time=T0 + number, plant="p", alarm="level_hi", transition="activated", state="unacknowledged",
                                previous="normal", priority="high", severity=severity, message=message, value="95.0", user="", origin="",
                                role="", comment="", sequence=number))


def start(settings: StorageSettings) -> tuple[Database, BatchWriter]:
    database = Database(settings)
    writer = BatchWriter(database, name="test-writer", flush_period=30.0)  # flushed by the test only
    writer.register(AuditSink("p", partition=86400.0, retention=None, now=lambda: T0))
    writer.register(JournalSink(None, lambda: T0))
    writer.register(HistorySink("p", [TagInfo("note", "string", stepped=True), TagInfo("level", "float64")]))
    assert writer.start() is None
    return database, writer


def test_text_that_no_store_can_encode_is_stored_escaped_and_the_rows_behind_it_are_written(storage_settings: StorageSettings) -> None:
    database, writer = start(storage_settings)
    try:
        writer.put("audit", [WriteEvent(T0 + 1, ALICE, "note", "idle", NOT_UTF8, Rule.TYPE_MISMATCH, "not text"),
                             WriteEvent(T0 + 2, ALICE, "note", "idle", "fine", None, "")])
        writer.put(TABLE, [journal_entry(1, f"operator wrote {NOT_UTF8}"), journal_entry(2, "nul\x00inside")])
        writer.put(SINK_NAME, [("note", T0 + 1, f"a{NOT_UTF8}b", 0), ("level", T0 + 1, 1.5, 0), ("note", T0 + 2, "plain", 0)])
        assert writer.flush(timeout=20), writer.stats.last_error
        assert writer.stats.pending == 0 and writer.stats.set_aside == 0 and writer.stats.escaped >= 3
        audit = sorted(search(database, AuditQuery(), "p"), key=lambda entry: entry.time)
        assert [(entry.new, entry.accepted) for entry in audit] == [("\\xff\\xfe", False), ("fine", True)]
        journal = AlarmJournal(database, writer, "p").search(JournalQuery())
        nul = "nul\\x00inside" if database.postgresql else "nul\x00inside"  # PostgreSQL's text cannot hold a NUL; SQLite's can
        assert sorted(entry.message for entry in journal) == [nul, "operator wrote \\xff\\xfe"]
        reader = HistoryReader(database, "p")
        try:
            assert [sample.value for sample in reader.raw("note", T0, T0 + 10).samples] == ["a\\xff\\xfeb", "plain"]
            assert [sample.value for sample in reader.raw("level", T0, T0 + 10).samples] == [1.5]
        finally:
            reader.close()
        # the store goes on: the next flush needs no escaping
        writer.put("audit", [WriteEvent(T0 + 3, ALICE, "note", "fine", "later", None, "")])
        assert writer.flush(timeout=20)
        assert len(search(database, AuditQuery(), "p")) == 3
    finally:
        writer.stop()


def test_a_row_that_still_cannot_be_written_is_set_aside_and_reported(storage_settings: StorageSettings, caplog) -> None:
    database, writer = start(storage_settings)
    caplog.set_level(logging.ERROR, logger="softplc.storage.writer")
    try:
        too_large = journal_entry(2, "severity beyond any integer column", severity=2**70)
        writer.put(TABLE, [journal_entry(1), too_large, journal_entry(3)])
        writer.put("audit", [WriteEvent(T0 + 1, ALICE, "note", "idle", "behind it", None, "")])
        assert writer.flush(timeout=20), writer.stats.last_error
        assert writer.stats.pending == 0 and writer.stats.set_aside == 1 and writer.stats.errors == 0
        assert sorted(entry.sequence for entry in AlarmJournal(database, writer, "p").search(JournalQuery())) == [1, 3]
        assert [entry.new for entry in search(database, AuditQuery(), "p")] == ["behind it"]
        reported = [record.getMessage() for record in caplog.records if "set aside" in record.getMessage()]
        assert len(reported) == 1 and TABLE in reported[0] and "severity beyond any integer column" in reported[0]
        assert writer.set_aside_rows[-1][0] == TABLE and writer.set_aside_rows[-1][1] == too_large
    finally:
        writer.stop()


def test_escaping_keeps_what_can_be_written_and_rebuilds_only_what_changed() -> None:
    assert escape_text("Grüße – ok") == "Grüße – ok"
    assert escape_text(NOT_UTF8 + "x\ud800") == "\\xff\\xfex\\ud800"
    assert escape_text("a\x00b") == "a\\x00b" and escape_text("a\x00b", nul=False) == "a\x00b"
    event = WriteEvent(T0, ALICE, "note", "idle", {"list": [NOT_UTF8]}, None, "")
    clean = escaped(event)
    assert clean is not event and clean.new == {"list": ["\\xff\\xfe"]} and clean.origin is event.origin
    unchanged = ("level", T0, 1.5, Quality.GOOD)  # any object that holds no string comes back as it is
    assert escaped(unchanged) is unchanged
    row = journal_entry(1)
    assert escaped(row) is row  # a clean row: nothing rebuilt
    dataclass_row = JournalEntry(*journal_entry(1))
    assert escaped(dataclass_row) is dataclass_row


async def test_an_opcua_write_of_invalid_utf8_does_not_stop_the_audit_trail(tmp_path: Path) -> None:
    async with running(tmp_path) as runtime:
        async with opcua_client(runtime, "operator") as operator:
            ns = await operator.get_namespace_index("urn:softplc:tags")
            name = operator.get_node(ua.NodeId("name", ns))
            # asyncua encodes the str with surrogateescape: the server receives the bytes ff fe
            await operator.write_values([name], [ua.DataValue(ua.Variant(NOT_UTF8, ua.VariantType.String))], raise_on_partial_error=False)
            level = operator.get_node(ua.NodeId("level", ns))
            await level.write_value(ua.DataValue(ua.Variant(12.5, ua.VariantType.Float)))
            await wait_until(lambda: runtime.db.value("level") == 12.5)
        found = await entries(runtime)
        assert [(entry.name, entry.new) for entry in found][-2:] == [("name", "\\xff\\xfe"), ("level", 12.5)]
