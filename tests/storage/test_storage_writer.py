"""The shared storage layer: one writer thread, batched transactions, on SQLite and PostgreSQL."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest

from softplc.config.yamlsource import parse_yaml
from softplc.storage import BatchWriter, Database, StorageError, StorageSettings, parse_span, storage_problems


class Notes:
    """A minimal sink: (number, text) rows in a table `notes`; can be told to fail once."""

    name = "notes"

    def __init__(self) -> None:
        self.fail_next = False
        self.prepared = 0
        self.maintained = 0
        self.threads: set[str] = set()

    def prepare(self, connection: Any, database: Database) -> None:
        self.prepared += 1
        connection.cursor().execute("CREATE TABLE IF NOT EXISTS notes (number INTEGER, text TEXT)")

    def write(self, connection: Any, database: Database, rows: list[Any]) -> None:
        self.threads.add(threading.current_thread().name)
        connection.cursor().executemany(database.sql("INSERT INTO notes VALUES (?, ?)"), rows)
        if self.fail_next:
            self.fail_next = False
            raise StorageError("simulated failure after the inserts")

    def maintain(self, connection: Any, database: Database) -> None:
        self.maintained += 1
        connection.cursor().execute(database.sql("DELETE FROM notes WHERE number < ?"), (0,))


def stored(database: Database) -> list[tuple[int, str]]:
    connection = database.connect(readonly=True)
    try:
        cursor = connection.cursor()
        cursor.execute("SELECT number, text FROM notes ORDER BY number")
        return [tuple(row) for row in cursor.fetchall()]
    finally:
        connection.close()


def test_rows_are_committed_in_batches_by_one_thread(storage_settings: StorageSettings) -> None:
    database = Database(storage_settings)
    sink = Notes()
    writer = BatchWriter(database, name="test-writer")
    writer.register(sink)
    assert writer.start() is None
    for number in range(1000):
        writer.put("notes", [(number, f"n{number}")])
    assert writer.flush(timeout=20)
    assert len(stored(database)) == 1000
    assert writer.stats.rows_written == 1000
    assert writer.stats.transactions < 1000  # batched, not one commit per row
    assert sink.threads == {"test-writer"}
    writer.stop()


def test_rows_are_committed_every_flush_period_without_being_asked(tmp_path: Path) -> None:
    # Rows put at a steady pace for 2 s with a 0.2 s flush period: about ten commits. The default
    # period (1 s) would give 2-3, a writer that commits only when asked none. (Commits late under
    # load lower the count; 4 leaves room for that and still tells 0.2 s from 1 s.)
    database = Database(StorageSettings.sqlite(tmp_path / "s.sqlite"))
    writer = BatchWriter(database, name="periodic-writer", flush_period=0.2)
    writer.register(Notes())
    assert writer.start() is None
    try:
        started = time.monotonic()
        number = 0
        while time.monotonic() - started < 2.0:
            writer.put("notes", [(number, "n")])
            number += 1
            time.sleep(0.01)
        deadline = time.monotonic() + 10.0
        while writer.stats.rows_written < number:  # the last rows: within a period or two, no flush asked
            assert time.monotonic() < deadline, f"{writer.stats.rows_written} of {number} rows committed 10 s later"
            time.sleep(0.02)
        assert writer.stats.transactions >= 4, f"{writer.stats.transactions} commits in 2 s with a 0.2 s flush period"
    finally:
        writer.stop()
    assert len(stored(database)) == number


def test_a_failed_transaction_keeps_its_rows_for_the_next_flush(storage_settings: StorageSettings) -> None:
    database = Database(storage_settings)
    sink = Notes()
    writer = BatchWriter(database)
    writer.register(sink)
    writer.start()
    sink.fail_next = True
    writer.put("notes", [(1, "a"), (2, "b")])
    assert not writer.flush(timeout=20)  # the failure is reported...
    writer.put("notes", [(3, "c")])
    assert writer.flush(timeout=20)  # ...and the next flush writes everything once
    assert stored(database) == [(1, "a"), (2, "b"), (3, "c")]
    assert writer.stats.errors == 1 and writer.stats.dropped == 0
    assert sink.prepared == 2  # reconnected after the failure
    writer.stop()


def test_stop_commits_what_is_queued_and_maintain_runs_on_request(storage_settings: StorageSettings) -> None:
    database = Database(storage_settings)
    sink = Notes()
    writer = BatchWriter(database, flush_period=30.0)  # never flushes by itself during the test
    writer.register(sink)
    writer.start()
    writer.put("notes", [(-1, "old"), (7, "kept")])
    assert writer.flush(timeout=20, maintain=True)
    assert sink.maintained == 1 and stored(database) == [(7, "kept")]
    writer.put("notes", [(8, "at stop")])
    writer.stop()
    assert stored(database) == [(7, "kept"), (8, "at stop")]


def test_a_full_queue_drops_the_oldest_rows_and_counts_them(tmp_path: Path) -> None:
    writer = BatchWriter(Database(StorageSettings.sqlite(tmp_path / "s.sqlite")), max_pending=5, flush_period=30.0)
    writer.register(Notes())
    writer.put("notes", [(n, "x") for n in range(8)])
    assert writer.stats.dropped == 3 and writer.stats.pending == 5
    writer.start()
    writer.stop()
    assert [number for number, _ in stored(writer.database)] == [3, 4, 5, 6, 7]


def test_an_unreachable_server_is_reported_and_retried(tmp_path: Path) -> None:
    settings = StorageSettings.postgresql("host=127.0.0.1 port=1 dbname=none connect_timeout=1", flush_period=0.05)
    writer = BatchWriter(Database(settings))
    writer.register(Notes())
    error = writer.start()
    assert isinstance(error, StorageError) and "127.0.0.1" in str(error)
    writer.put("notes", [(1, "kept while the server is away")])
    assert writer.stats.pending == 1
    writer.stop(timeout=5)


def test_settings_from_a_section_and_their_problems(tmp_path: Path) -> None:
    text = "h:\n  backend: postgresql\n  flush_period: 2min\n  path: x.sqlite\n"
    data, source = parse_yaml(text, "t.yaml")
    messages = [str(problem) for problem in storage_problems(data["h"], ("h",), source)]
    assert messages == [
        "t.yaml:2:12: backend postgresql needs a dsn, e.g. dsn: 'host=127.0.0.1 port=5432 dbname=plant'",
        "t.yaml:4:3: path is for backend: sqlite (this section uses postgresql)",
        "t.yaml:3:17: flush_period must be more than 0 and at most 60s, not 2min",
    ]
    settings = StorageSettings.from_section({"flush_period": "250ms"}, tmp_path, "history.sqlite")
    assert settings.backend == "sqlite" and settings.path == tmp_path / "history.sqlite" and settings.flush_period == 0.25
    shown = StorageSettings.postgresql("host=h password=secret dbname=d").describe()
    assert "secret" not in shown and "password=***" in shown
    assert parse_span("30d") == 30 * 86400 and parse_span("1w") == 604800 and parse_span("2h") == 7200
    with pytest.raises(ValueError):
        parse_span("3 fortnights")
