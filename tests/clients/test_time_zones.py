"""One rule for times in every command: without a zone a time is UTC, and every time shown has its zone (issue 21, item 13).

Reproduction: with TZ=America/New_York, `softplc alarms journal --since T` read T as New York
time and `softplc audit --since T` the same text as UTC (0 rows vs 12); the server-side
`alarms.journal` command used the runtime host's zone; the journal table printed local times
without a zone. Both command lines run here as the user runs them, in processes of their own
with TZ set, against one running plant.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path

import pytest
from asyncua import ua

from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.util.timestamps import format_shown, parse_time, parse_utc
from tests.audit_support import PASSWORDS, adapter, opcua_client, running, softplc, wait_until

ZONE = "America/New_York"  # UTC-5 in November: a local reading of a time moves it by five hours


@pytest.fixture
def new_york(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """This process and the command lines it starts in New York's zone (as the runtime host and as the user)."""
    monkeypatch.setenv("TZ", ZONE)
    time.tzset()
    try:
        yield
    finally:
        monkeypatch.undo()
        time.tzset()


def naive_utc(seconds: float) -> str:
    """A time as a user would type it from a UTC table: ISO 8601 without a zone."""
    return datetime.fromtimestamp(seconds, timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")


def shown_times(output: str) -> list[float]:
    """The times in the first column of a table (after its header)."""
    times = []
    for line in output.splitlines()[1:]:
        if line.strip() and not set(line.strip()) <= set("-─ "):
            day, clock = line.split()[:2]
            assert clock.endswith("Z"), f"a time without its zone: {line!r}"
            times.append(parse_utc(f"{day}T{clock}"))
    return times


async def test_both_command_lines_and_the_journal_command_read_a_time_without_a_zone_as_utc(tmp_path: Path, new_york: None) -> None:
    async with running(tmp_path) as runtime:
        endpoint = adapter(runtime, "opcua").endpoint
        before = time.time()
        since = naive_utc(before - 60)
        async with opcua_client(runtime, "operator") as operator:
            ns = await operator.get_namespace_index("urn:softplc:tags")
            await operator.get_node(ua.NodeId("level", ns)).write_value(ua.DataValue(ua.Variant(95.0, ua.VariantType.Float)))
        await wait_until(lambda: runtime.db.value("_sys.alarms.unacknowledged") == 1)
        after = time.time() + 1

        code, out, err = await softplc("audit", "--since", since, "--endpoint", endpoint, "--user", "engineer", home=tmp_path,
                                       password=PASSWORDS["engineer"])
        assert code == 0, err
        assert "level" in out
        assert all(before - 1 <= moment <= after for moment in shown_times(out))

        code, out, err = await softplc("alarms", "journal", "--since", since, "--endpoint", endpoint, home=tmp_path)
        assert code == 0, err
        assert "level_hi" in out and "activated" in out, err
        assert shown_times(out) and all(before - 1 <= moment <= after for moment in shown_times(out))

        # the server side: the runtime host is in New York too, and reads the same text as UTC
        viewer = Origin("cli", "viewer", role=Role.VIEWER)
        rows = await runtime.commands.call("alarms.journal", {"since": since}, viewer)
        assert [row["alarm"] for row in rows] == ["level_hi"]
        later = naive_utc(after + 60)
        assert await runtime.commands.call("alarms.journal", {"since": later}, viewer) == []


def test_the_rule_itself() -> None:
    os_zone = os.environ.get("TZ")
    assert parse_utc("2026-11-27T00:27:50") == parse_utc("2026-11-27T00:27:50Z") == parse_utc("2026-11-26T19:27:50-05:00")
    assert parse_time("2026-11-27 00:27:50Z", now=0.0) == 1795739270.0
    assert parse_time("8h", now=1795739270.0) == 1795739270.0 - 8 * 3600
    assert parse_time("7d", now=1795739270.0) == 1795739270.0 - 7 * 86400
    assert format_shown(1795739270.0) == "2026-11-27 00:27:50Z"
    assert format_shown(1795739270.25, milliseconds=True) == "2026-11-27 00:27:50.250Z"
    with pytest.raises(ValueError, match="UTC unless a zone is given"):
        parse_time("yesterday", now=0.0)
    assert os.environ.get("TZ") == os_zone
