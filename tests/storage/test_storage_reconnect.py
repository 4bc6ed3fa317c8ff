"""After a PostgreSQL restart every reader and writer reconnects by itself, and says so (issue 21, item 6).

A server of its own (tests/postgres_server.py), stopped as an administrator would (`pg_ctl stop -m
fast` terminates the clients' connections) and started again on the same port. Before the fix the
history reader kept its dead connection ("the connection is closed" until the runtime restarted)
and an idle writer's retention pass reused its dead connection every time, logging an ERROR.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from tools_support import missing

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import parse_config
from softplc.core.clock import RealClock
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.storage import BatchWriter, Database, StorageSettings
from softplc.storage.alarm_journal import TABLE, JournalSink
from tests.conftest import REPO
from tests.storage.test_storage_unwritable import journal_entry

SUPPORT = REPO / "tests" / "history_support.py"
VIEWER = Origin("hmi", "viewer", role=Role.VIEWER)


@pytest.fixture(scope="module")
def server() -> Iterator[object]:
    from tests.postgres_server import PostgresServer, PostgresUnavailable

    try:
        postgres = PostgresServer()
    except PostgresUnavailable as error:
        missing(str(error))
    postgres.start()
    try:
        yield postgres
    finally:
        postgres.stop()


def restart(server: object, down: float = 0.5) -> None:
    """Stop the server (its clients' connections are cut), keep it down `down` seconds, start it again."""
    server.shut_down()  # type: ignore[attr-defined]
    time.sleep(down)  # the outage itself: what the test is about, not a wait for a condition
    server.start_again()  # type: ignore[attr-defined]


async def wait_for(condition: Callable[[], bool], timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout} s")
        await asyncio.sleep(0.02)


def said(caplog: pytest.LogCaptureFixture, writer: str, text: str) -> bool:
    return any(record.getMessage().startswith(f"{writer}: {text}") for record in caplog.records)


async def test_history_reads_and_writes_go_on_after_a_postgresql_restart(server: object, tmp_path: Path, caplog) -> None:
    caplog.set_level(logging.INFO, logger="softplc.storage")
    dsn = server.new_schema("history_restart")  # type: ignore[attr-defined]
    config = parse_config(f"""
version: 1
plant: {{name: restart}}
tags:
  tick: {{type: uint32}}
  value: {{type: float64}}
tasks:
  fast:
    interval: 50ms
    programs:
      - {{name: flood, program: "{SUPPORT}:Flood", bind: {{tick: tick, values: [value]}}}}
servers: {{opcua: {{enabled: false}}, modbus: {{enabled: false}}, hmi: {{enabled: false}}}}
history:
  backend: postgresql
  dsn: "{dsn}"
  flush_period: 100ms
  record: [{{tags: ["tick"]}}]
""", tmp_path / "tagdb.yaml")
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    try:
        async def read() -> list[dict]:
            now = runtime.clock.wall()
            return (await runtime.commands.call("history.read_raw", {"tag": "tick", "start": now - 3600, "end": now + 1}, VIEWER))["samples"]

        await wait_for(lambda: runtime.db.value("tick") > 5)
        recorder = next(adapter for adapter in runtime.adapters if adapter.name == "history")
        assert await asyncio.to_thread(recorder.flush, 10.0)
        assert await read()  # the reader's connection is open
        await asyncio.to_thread(restart, server)
        back = runtime.clock.wall()
        await wait_for(lambda: said(caplog, "softplc-history-writer", "reconnected"))
        samples = await read()  # the first read after the restart: no "the connection is closed"
        # The writer can reconnect before the restart is seen to end: what is recorded from `back` on
        # reaches the store a flush later, and is read.
        deadline = time.monotonic() + 10.0
        while samples[-1]["time"] <= back:
            assert time.monotonic() < deadline, f"nothing recorded after the restart was read back: last {samples[-1]}"
            assert await asyncio.to_thread(recorder.flush, 10.0)
            samples = await read()
        ticks = [sample["value"] for sample in samples]
        assert ticks == list(range(ticks[0], ticks[-1] + 1))  # nothing lost across the outage
    finally:
        await runtime.stop()


async def test_an_idle_writer_reconnects_says_so_and_reports_no_error_afterwards(server: object, caplog) -> None:
    caplog.set_level(logging.INFO, logger="softplc.storage")
    dsn = server.new_schema("idle_restart")  # type: ignore[attr-defined]
    writer = BatchWriter(Database(StorageSettings.postgresql(dsn, flush_period=0.05)), name="idle-writer", maintain_period=0.2)
    writer.register(JournalSink(retention=3600.0, now=time.time))
    assert writer.start() is None
    try:
        writer.put(TABLE, [journal_entry(1)])
        assert writer.flush(timeout=10)
        await asyncio.to_thread(restart, server)
        # nothing to write: only the retention pass finds the connection dead
        await wait_for(lambda: said(caplog, "idle-writer", "reconnected"))
        errors = writer.stats.errors
        assert await asyncio.to_thread(writer.flush, 10.0, maintain=True)  # retention runs on the new connection
        assert await asyncio.to_thread(writer.flush, 10.0, maintain=True)
        assert writer.stats.errors == errors
        writer.put(TABLE, [journal_entry(2)])
        assert await asyncio.to_thread(writer.flush, 10.0)
    finally:
        writer.stop()
