"""The writer in a process of its own (softplc/storage/process.py): what a thread does, and it survives its own death.

Real child processes (`python -m softplc.storage.child`) writing real stores; killed with
SIGKILL, sent SIGINT as a terminal's Ctrl-C would, on SQLite and PostgreSQL.
"""

from __future__ import annotations

import logging
import os
import signal
import time
from collections.abc import Callable

import pytest

from softplc.adapters.history.queries import HistoryReader
from softplc.adapters.history.store import SINK_NAME, HistorySink, TagInfo
from softplc.storage import Database, StorageSettings
from softplc.storage.process import ProcessWriter

T0 = 1_767_225_600.0


def rows(first: int, count: int) -> list[tuple[str, float, float, int]]:
    return [("level", T0 + number, float(number), 0) for number in range(first, first + count)]


def stored(database: Database) -> list[float]:
    reader = HistoryReader(database, "p")
    try:
        return [sample.value for sample in reader.raw("level", T0, T0 + 1e6).samples]
    finally:
        reader.close()


def wait_for(condition: Callable[[], bool], timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout} s")
        time.sleep(0.02)


@pytest.fixture
def writer(storage_settings: StorageSettings):
    process = ProcessWriter(Database(storage_settings), name="test-process-writer")
    process.register(HistorySink("p", [TagInfo("level", "float64")]))
    assert process.start() is None
    yield process
    process.stop()


def test_rows_are_committed_by_the_child_and_counted_here(writer: ProcessWriter) -> None:
    for first in range(0, 1000, 100):
        writer.put(SINK_NAME, rows(first, 100))
    assert writer.flush(timeout=20)
    assert stored(writer.database) == [float(number) for number in range(1000)]
    wait_for(lambda: writer.stats.rows_written == 1000)
    assert writer.stats.pending == 0 and writer.stats.transactions >= 1
    writer.put(SINK_NAME, rows(1000, 5))
    writer.stop()  # commits what was queued
    assert len(stored(writer.database)) == 1005


def test_a_child_that_dies_is_replaced_and_its_rows_are_counted_as_lost(writer: ProcessWriter, caplog) -> None:
    caplog.set_level(logging.ERROR, logger="softplc.storage.process")
    writer.put(SINK_NAME, rows(0, 10))
    assert writer.flush(timeout=20)
    first = writer._process
    assert first is not None
    os.kill(first.pid, signal.SIGKILL)
    wait_for(lambda: writer._process is not first and writer._process is not None and writer._process.poll() is None)
    assert any("ended unexpectedly" in record.getMessage() for record in caplog.records)
    writer.put(SINK_NAME, rows(10, 10))
    assert writer.flush(timeout=20)
    assert stored(writer.database) == [float(number) for number in range(20)]
    assert writer.stats.dropped == 0  # it held nothing when it died: everything was committed before


def test_a_ctrl_c_for_the_process_group_does_not_stop_the_child(writer: ProcessWriter) -> None:
    process = writer._process
    assert process is not None
    os.kill(process.pid, signal.SIGINT)
    os.kill(process.pid, signal.SIGTERM)
    writer.put(SINK_NAME, rows(0, 3))
    assert writer.flush(timeout=20)  # the runtime's orderly stop is what ends it
    assert process.poll() is None and stored(writer.database) == [0.0, 1.0, 2.0]


def test_an_unreachable_server_is_reported_at_start_and_rows_wait(tmp_path) -> None:
    settings = StorageSettings.postgresql("host=127.0.0.1 port=1 dbname=none connect_timeout=1", flush_period=0.05)
    process = ProcessWriter(Database(settings), name="unreachable")
    process.register(HistorySink("p", [TagInfo("level", "float64")]))
    error = process.start()
    try:
        assert error is not None and "127.0.0.1" in str(error)
        process.put(SINK_NAME, rows(0, 4))
        wait_for(lambda: process.stats.pending == 4 and process.stats.errors >= 1)
    finally:
        process.stop(timeout=5)


def test_rows_a_dying_child_held_are_counted_as_dropped(tmp_path, caplog) -> None:
    caplog.set_level(logging.ERROR, logger="softplc.storage.process")
    process = ProcessWriter(Database(StorageSettings.sqlite(tmp_path / "h.sqlite")), name="held", flush_period=30.0)
    process.register(HistorySink("p", [TagInfo("level", "float64")]))
    assert process.start() is None
    try:
        process.put(SINK_NAME, rows(0, 10))
        wait_for(lambda: process._child.get("pending") == 10)  # the child has them, and commits only in 30 s
        held = process._process
        assert held is not None
        os.kill(held.pid, signal.SIGKILL)
        # The count is updated under the writer's lock, the error line logged just after it.
        wait_for(lambda: process.stats.dropped == 10
                 and any("holding 10 rows, which are lost" in record.getMessage() for record in caplog.records))
        process.put(SINK_NAME, rows(10, 3))
        assert process.flush(timeout=30)  # to the child that replaced it
        assert stored(process.database) == [10.0, 11.0, 12.0] and process.stats.pending == 0
    finally:
        process.stop()
