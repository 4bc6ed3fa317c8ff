"""The audit adapter in a running plant: its configured backend, `audit.query` for engineers only, a store that is down or cannot be opened."""

from __future__ import annotations

import asyncio
import socket
import textwrap
from pathlib import Path

import pytest

from softplc.app.adapters import build_adapters
from softplc.app.runtime import AdapterError, Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.commands import CommandRefused
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.storage import Database
from softplc.storage.audit.queries import AuditQuery, search

PEOPLE = {role.value: Origin("hmi", role.value, "10.0.0.5:40000", role) for role in Role}
DRIVER = Origin("fleet:r01", role=None)

PLANT = """\
version: 1
plant: {name: recorder-test}
tags:
  level: {type: float64, min: 0, max: 100}
tasks:
  fast: {interval: 10ms}
servers:
  opcua: {enabled: false}
  modbus: {enabled: false}
  hmi: {enabled: false}
"""


async def start(tmp_path: Path, audit: str) -> Runtime:
    path = tmp_path / "tagdb.yaml"
    path.write_text(PLANT + textwrap.dedent(audit))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    return runtime


async def test_a_running_plant_audits_to_its_configured_backend(storage_settings, tmp_path: Path) -> None:
    if storage_settings.backend == "sqlite":
        section = f'audit: {{path: "{storage_settings.path}", flush_period: 50ms}}\n'
    else:
        section = f'audit: {{backend: postgresql, dsn: "{storage_settings.dsn}", flush_period: 50ms}}\n'
    runtime = await start(tmp_path, section)
    try:
        db = runtime.db
        assert db.submit([("level", 5.0)], PEOPLE["operator"]) == [None]
        db.submit([("level", 7.0)], DRIVER)  # code inside the runtime (a robot driver): not a client's write
        assert db.submit([("level", 500.0)], PEOPLE["operator"])[0] is not None
        with pytest.raises(CommandRefused, match="role operator may not read the audit trail"):
            await runtime.commands.call("audit.query", {}, PEOPLE["operator"])
        with pytest.raises(CommandRefused, match="role viewer may not read the audit trail"):
            await runtime.commands.call("audit.query", {}, PEOPLE["viewer"])
        rows = await runtime.commands.call("audit.query", {"tag": "level"}, PEOPLE["engineer"])
        assert [(row["new"], row["accepted"], row["rule"], row["user"], row["plant"]) for row in rows] == [
            (500.0, False, "out of range", "operator", "recorder-test"), (5.0, True, "", "operator", "recorder-test")]
        assert rows[0]["time_utc"].endswith("Z") and rows[0]["peer"] == "10.0.0.5:40000"
        rows = await runtime.commands.call("audit.query", {"result": "accepted", "limit": 5, "since": "2000-01-01T00:00:00Z"}, PEOPLE["engineer"])
        assert [row["new"] for row in rows] == [5.0]
        for arguments, message in [({"limit": -1}, "'limit' must be a whole number ≥ 0"), ({"result": "maybe"}, "'result' must be accepted or refused"),
                                   ({"since": "yesterday"}, "'since' must be epoch seconds or an ISO 8601 time"),
                                   ({"kind": "read"}, "'kind' must be write or command"), ({"tag": 3}, "'tag' must be text"),
                                   ({"tags": "x"}, "unknown argument 'tags'")]:
            with pytest.raises(CommandRefused, match=message):
                await runtime.commands.call("audit.query", arguments, PEOPLE["engineer"])
    finally:
        await runtime.stop()
    # Committed: a reader that is not the runtime finds them; reading the trail is not itself in it.
    found = search(Database(storage_settings), AuditQuery(), "recorder-test")
    assert [(entry.kind, entry.name, entry.new) for entry in found] == [("write", "level", 500.0), ("write", "level", 5.0)]


async def test_the_plant_keeps_running_while_a_postgresql_store_is_down_and_says_so(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    with socket.socket() as probe:  # a loopback port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    runtime = await start(tmp_path, f'audit: {{backend: postgresql, dsn: "host=127.0.0.1 port={port} dbname=plant connect_timeout=2"}}\n')
    try:
        assert "audit: PostgreSQL host=127.0.0.1" in caplog.text and "entries are kept in memory" in caplog.text
        assert runtime.db.submit([("level", 5.0)], PEOPLE["operator"]) == [None]
        cycles = runtime.tasks[0].stats.cycles
        with pytest.raises(CommandRefused, match="the audit trail cannot be read now"):
            await runtime.commands.call("audit.query", {}, PEOPLE["engineer"])
        recorder = next(adapter for adapter in runtime.adapters if adapter.name == "audit")
        assert recorder.writer.stats.pending == 1  # kept for when the store is back
        await asyncio.sleep(0.1)
        assert runtime.tasks[0].stats.cycles > cycles  # still scanning
    finally:
        await runtime.stop()


async def test_a_sqlite_store_that_cannot_be_opened_stops_the_start_with_the_reason(tmp_path: Path) -> None:
    (tmp_path / "state" / "audit.sqlite").mkdir(parents=True)  # a directory where the file should be
    with pytest.raises(AdapterError, match=r"audit: cannot open SQLite .*audit\.sqlite: .*audit: \{enabled: false\}"):
        await start(tmp_path, "")
