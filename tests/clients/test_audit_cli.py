"""`softplc audit`: the store read directly (plant running or stopped, --sim's own), or a running runtime asked over OPC UA."""

from __future__ import annotations

import argparse
import asyncio
import csv
import io
import json
import re
import textwrap
from pathlib import Path

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from tests.audit_support import PASSWORDS, adapter, running, softplc, wait_until

ALICE = Origin("opcua", "alice", "10.0.0.7:51022", Role.OPERATOR)
BOB = Origin("hmi", "bob", "10.0.0.9:40001", Role.ENGINEER)
EPOCH = 1_767_225_600.0  # SimClock's wall-clock origin


def rows(text: str) -> list[list[str]]:
    """A printed table's rows (columns split on two or more spaces)."""
    return [re.split(r"\s{2,}", line.strip()) for line in text.splitlines()[2:]]


async def test_the_store_is_read_with_the_plant_stopped_with_filters_and_formats(tmp_path: Path) -> None:
    async with running(tmp_path, no_servers=True) as runtime:
        db = runtime.db
        assert db.submit([("level", 42.5), ("setpoint", 500)], ALICE)[0] is None
        await wait_until(lambda: db.value("level") == 42.5)
        await runtime.commands.call("tags.force", {"tag": "level", "value": "55"}, BOB)
    config, state = str(tmp_path / "tagdb.yaml"), str(tmp_path / "state")
    code, out, err = await softplc("audit", "--config", config, "--state-dir", state, home=tmp_path)
    assert code == 0, err
    assert out.splitlines()[0].split() == ["time", "source", "user", "peer", "tag", "/", "command", "old", "new", "result"]
    assert all(row[0].endswith("Z") for row in rows(out))  # every time shows its zone (UTC)
    assert [row[1:] for row in rows(out)] == [
        ["hmi", "bob", "10.0.0.9:40001", "tags.force level", "42.5", "55.0", "accepted"],
        ["opcua", "alice", "10.0.0.7:51022", "setpoint", "0", "500", "refused: out of range: 500 is above the maximum 100"],
        ["opcua", "alice", "10.0.0.7:51022", "level", "0.0", "42.5", "accepted"],
    ]
    code, out, err = await softplc("audit", "--config", config, "--state-dir", state, "--refused", "--since", "1h", "--format", "csv", home=tmp_path)
    assert code == 0, err
    table = list(csv.DictReader(io.StringIO(out)))
    assert [(row["user"], row["name"], row["rule"]) for row in table] == [("alice", "setpoint", "out of range")]
    code, out, err = await softplc("audit", "--config", config, "--state-dir", state, "--by", "bob", "--tag", "lev*", "--format", "json", home=tmp_path)
    assert code == 0, err
    [entry] = json.loads(out)
    assert {k: entry[k] for k in ("kind", "name", "tag", "old", "new", "arguments", "accepted")} == {
        "kind": "command", "name": "tags.force", "tag": "level", "old": 42.5, "new": 55.0, "arguments": {"tag": "level", "value": "55"}, "accepted": True}
    code, out, err = await softplc("audit", "--config", config, "--state-dir", state, "--until", "2000-01-01T00:00", home=tmp_path)
    assert (code, out, err.strip()) == (0, "", "no audit entries match")
    # --user logs in (with --endpoint); the filter is --by
    code, _, err = await softplc("audit", "--config", config, "--state-dir", state, "--user", "bob", home=tmp_path)
    assert code == 2 and "to show the entries of bob write --by bob" in err
    code, _, err = await softplc("audit", "--config", config, "--state-dir", state, "--since", "yesterday", home=tmp_path)
    assert code == 2 and "--since 'yesterday': write how long ago" in err
    code, _, err = await softplc("audit", "--config", config, "--state-dir", str(tmp_path / "nowhere"), home=tmp_path)
    assert code == 1 and "no audit trail yet: SQLite" in err and "it is created by `softplc run`" in err


async def test_a_running_runtime_is_asked_over_opcua_by_engineers_only(tmp_path: Path) -> None:
    async with running(tmp_path) as runtime:
        endpoint = adapter(runtime, "opcua").endpoint
        runtime.db.submit([("setpoint", 5)], ALICE)
        for index in range(1, 1201):  # more than one page of audit.query (1,000)
            runtime.db.submit([("setpoint", 200 + index)], ALICE)
        code, out, err = await softplc("audit", "--endpoint", endpoint, "--user", "engineer", "--tag", "setpoint", "--limit", "2",
                                       home=tmp_path, password=PASSWORDS["engineer"])
        assert code == 0, err
        assert [row[2:5] for row in rows(out)] == [["alice", "10.0.0.7:51022", "setpoint"]] * 2
        assert rows(out)[0][6:] == ["1400", "refused: out of range: 1400 is above the maximum 100"]
        code, out, err = await softplc("audit", "--endpoint", endpoint, "--user", "engineer", "--format", "json", "--refused",
                                       home=tmp_path, password=PASSWORDS["engineer"])
        assert code == 0, err
        assert [entry["new"] for entry in json.loads(out)] == list(range(1400, 200, -1))
        for user in ("operator", None):
            login = ["--user", user] if user else []
            code, out, err = await softplc("audit", "--endpoint", endpoint, *login, home=tmp_path, password=PASSWORDS.get(user or ""))
            assert (code, out) == (4, ""), err
            assert "reading the audit trail needs the engineer role" in err
        code, _, err = await softplc("audit", "--endpoint", "opc.tcp://127.0.0.1:9/softplc/", home=tmp_path)
        assert code == 3, err


async def test_a_simulated_run_keeps_its_own_trail_on_the_simulated_clock(tmp_path: Path) -> None:
    (tmp_path / "tagdb.yaml").write_text(textwrap.dedent("""
        version: 1
        plant: {name: sim-audit}
        tags:
          level: {type: float64}
        tasks:
          scan: {interval: 100ms}
        """))
    config = load_config(tmp_path / "tagdb.yaml")
    for run in range(2):  # the second run replaces the first one's trail
        runtime = Runtime(config, SimClock(), state_dir=tmp_path / "state", retain=False)
        for item in build_adapters(config, argparse.Namespace(sim=True, no_servers=True)):
            runtime.add_adapter(item)
        await runtime.start()
        try:
            await runtime.clock.sleep(2.5)
            runtime.db.submit([("level", float(run))], ALICE)
            await runtime.clock.sleep(1.0)
            runtime.db.submit([("level", 10.0 + run)], ALICE)
            await asyncio.sleep(0)
        finally:
            await runtime.stop()
    assert not (tmp_path / "state" / "audit.sqlite").exists()  # the real plant's trail is never touched
    assert (tmp_path / "state" / "audit-sim.sqlite").exists()
    code, out, err = await softplc("audit", "--config", str(tmp_path / "tagdb.yaml"), "--state-dir", str(tmp_path / "state"), "--sim",
                                   "--format", "json", home=tmp_path)
    assert code == 0, err
    assert [(entry["time_utc"], entry["new"]) for entry in json.loads(out)] == [("2026-01-01T00:00:03.500Z", 11.0), ("2026-01-01T00:00:02.500Z", 1.0)]
    code, out, err = await softplc("audit", "--config", str(tmp_path / "tagdb.yaml"), "--state-dir", str(tmp_path / "state"), "--sim",
                                   "--since", "0.5s", "--format", "json", home=tmp_path)
    assert code == 0, err
    assert [entry["time"] - EPOCH for entry in json.loads(out)] == [3.5]  # counted back from the run's last entry
