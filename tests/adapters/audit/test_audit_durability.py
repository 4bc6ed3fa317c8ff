"""kill -9 while a Modbus client writes as fast as it can: the audit store stays intact and loses at most the flush period.

A real `softplc run` child serves Modbus TCP; a pymodbus client writes 1, 2, 3... into one
int32 tag, each write acknowledged before the next (a few thousand writes a second). The test
kills the child with SIGKILL in the middle of it, then checks on SQLite and on PostgreSQL that
the store is intact, that every write recorded is there without a gap from the first one on,
and that the writes acknowledged but not recorded span at most the flush period.
"""

from __future__ import annotations

import os
import re
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import REPO
from pymodbus.client import ModbusTcpClient

from softplc.adapters.modbus.server import ModbusAdapter
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.config import load_config
from softplc.storage import Database, StorageSettings
from softplc.storage.audit.queries import AuditQuery, search

FLUSH = 0.25  # s
# A commit takes its own time, and on a shared 2-core machine the child may wait for the CPU for
# hundreds of ms (tests/adapters/history/test_history_durability.py measured up to 0.55 s at load 7;
# this test, on PostgreSQL in fresh-clone suite runs at load ~6, lost 1.08 s and 1.11 s): the bound
# checked is the flush period plus this allowance. With the flush period wrongly at 2 s (or ignored
# for the default 1 s) the loss is up to that period plus the commit: caught only when the kill comes
# late in a period — tests/storage/test_storage_writer.py checks the period itself (commits counted).
COMMIT_ALLOWANCE = 1.25


def postgres_sessions(dsn: str, application: str, *, gone_within: float = 0.0) -> int:
    """How many sessions of `application` the server has — after waiting up to `gone_within` seconds for none."""
    import psycopg

    deadline = time.monotonic() + gone_within
    with psycopg.connect(dsn, autocommit=True) as connection:
        while True:
            left = connection.execute("SELECT count(*) FROM pg_stat_activity WHERE application_name = %s", (application,)).fetchone()[0]
            if not left or time.monotonic() >= deadline:
                return left
            time.sleep(0.02)


def plant(section: str) -> str:
    return f"""
version: 1
plant: {{name: durable}}
tags:
  counter: {{type: int32}}
tasks:
  fast:
    interval: 10ms
audit:
  {section}
  flush_period: {int(FLUSH * 1000)}ms
"""


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_kill_9_during_a_write_flood_keeps_every_write_before_the_last_flush(backend: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    if backend == "sqlite":
        section, settings = "backend: sqlite", StorageSettings.sqlite(tmp_path / "state" / "audit.sqlite")
    else:
        dsn = request.getfixturevalue("postgres_dsn")
        application = f"softplc-killed-{os.getpid()}-{time.monotonic_ns()}"  # names the runtime's sessions
        section, settings = f'backend: postgresql\n  dsn: "{dsn} application_name={application}"', StorageSettings.postgresql(dsn)
    path = tmp_path / "tagdb.yaml"
    path.write_text(plant(section))
    address = ModbusAdapter(load_config(path), ModbusSettings(port=0)).map.by_tag["counter"].address
    child = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "run", str(path), "--no-opcua", "--no-hmi", "--modbus-port", "0", "--no-status",
         "--state-dir", str(tmp_path / "state")],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO,
    )
    acknowledged: list[tuple[int, float]] = []  # (value, when its write was acknowledged)
    stop = threading.Event()

    def flood(port: int) -> None:
        client = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
        client.connect()
        value = 1
        try:
            while not stop.is_set():
                if client.write_registers(address, [value >> 16, value & 0xFFFF]).isError():  # an int32: two words, big-endian
                    break
                acknowledged.append((value, time.time()))
                value += 1
        except Exception:  # the server was killed under the client
            pass
        finally:
            client.close()

    try:
        assert child.stderr is not None
        port = 0
        deadline = time.monotonic() + 60
        while not port and time.monotonic() < deadline:
            line = child.stderr.readline()
            assert line, "softplc run ended before serving"
            if match := re.search(r"serving: Modbus TCP on 127\.0\.0\.1:(\d+)", line):
                port = int(match.group(1))
        assert port, "no Modbus server within 60 s"
        flooding = threading.Thread(target=flood, args=(port,), daemon=True)
        flooding.start()
        time.sleep(3.0)
        if backend == "postgresql":
            assert postgres_sessions(dsn, application) >= 1, "the runtime's audit writer has no session named by its DSN"
        killed_at = time.time()
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
        stop.set()
        flooding.join(timeout=30)
        if backend == "postgresql":
            # A COMMIT the writer sent just before the kill is still carried out by the server: read
            # the store once the killed runtime's sessions have ended, not while it commits.
            assert not postgres_sessions(dsn, application, gone_within=30), "the killed runtime's PostgreSQL sessions did not end"
    finally:
        stop.set()
        if child.poll() is None:
            child.kill()
            child.wait()
    assert len(acknowledged) > 1000, f"only {len(acknowledged)} writes in 3 s"
    if backend == "sqlite":
        with sqlite3.connect(settings.path) as connection:
            assert connection.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    entries = list(reversed(search(Database(settings), AuditQuery(tag="counter", limit=10_000), "durable")))
    while len(entries) % 10_000 == 0 and entries:  # more than one page
        more = search(Database(settings), AuditQuery(tag="counter", limit=10_000, offset=len(entries)), "durable")
        entries = list(reversed(more)) + entries
        if len(more) < 10_000:
            break
    values = [entry.new for entry in entries]
    # Nothing is missing before the last commit: every write, in order, each with its old value.
    assert values == list(range(1, len(values) + 1))
    assert all(entry.accepted and entry.source == "modbus" and entry.peer.startswith("127.0.0.1:") for entry in entries)
    assert len(values) >= 100
    when = dict(acknowledged)
    # What is lost is the writes the server acknowledged and the store does not have: from the last
    # recorded one to the last one acknowledged before the kill. A stretch at the end where the child
    # got no CPU and acknowledged nothing (its flush timer starved with it) loses nothing and is
    # reported, not counted.
    last_acknowledged = max(at for _, at in acknowledged if at <= killed_at)
    lost = last_acknowledged - when[values[-1]]
    print(f"{backend}: {len(acknowledged)} writes acknowledged, {len(values)} recorded; the last recorded one was "
          f"acknowledged {lost:.3f} s before the last acknowledged write, {killed_at - when[values[-1]]:.3f} s before "
          f"the kill (flush period {FLUSH} s)")
    assert lost <= FLUSH + COMMIT_ALLOWANCE, (
        f"lost {lost:.3f} s of acknowledged writes ({sum(when[values[-1]] < at <= last_acknowledged for _, at in acknowledged)} "
        f"writes), more than the flush period {FLUSH} s (+{COMMIT_ALLOWANCE} s)")
