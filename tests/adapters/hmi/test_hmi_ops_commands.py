"""Operating through the HMI's commands door (softplc/adapters/hmi/command_door.py) and the forced mark on the wire.

Real HTTP and WebSockets (aiohttp client) against a running runtime: forcing by an engineer, the
role refusals every path shares (403, reported to the command listeners like any refused call),
CSRF, refusals in the runtime's words, program control, an online change's refusal with its
details, the forced flag in live updates and in /api/tags, and the audit page's CSV export.
"""

from __future__ import annotations

import csv
import io
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
import pytest_asyncio
from hmi_support import Plant, http_client, http_login, post_command, receive_until, start_plant, wait_until

from softplc.core.commands import CommandCall

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_plant(tmp_path_factory.mktemp("hmi-commands"))
    plant.calls: list[CommandCall] = []  # type: ignore[misc]
    plant.runtime.commands.on_call(plant.calls.append)
    yield plant
    await plant.stop()


async def call(session: aiohttp.ClientSession, url: str, csrf: str | None, name: str, arguments: Any = None) -> tuple[int, Any]:
    status, body = await post_command(session, url, name, arguments, csrf)
    # Every answer says whether it succeeded and which command it was; what the tests compare is
    # the result (200) or the refusal's words and details.
    assert body["ok"] is (status == 200) and body["command"] == name, body
    return (status, body["result"]) if body["ok"] else (status, {key: body[key] for key in ("error", "details") if key in body})


async def test_an_engineer_forces_and_the_forced_mark_travels_with_the_live_value(plant: Plant) -> None:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_json({"type": "subscribe", "items": ["limit", "flag"]})
        snapshot = await receive_until(ws, lambda m: m["type"] == "snapshot")
        assert "forced" not in snapshot
        csrf = await http_login(session, plant.url, "engineer")
        status, result = await call(session, plant.url, csrf, "tags.force", {"tag": "limit", "value": "42.5"})
        assert status == 200 and result == "limit forced to 42.5 from the next cycle"
        update = await receive_until(ws, lambda m: m["type"] == "update" and "limit" in m["values"])
        assert update["values"]["limit"] == 42.5 and update["forced"] == ["limit"]
        assert "quality" not in update  # forced, yet good: the mark is separate from the quality
        async with session.get(plant.url + "api/tags/limit") as response:
            assert (await response.json())["forced"] is True
        status, forces = await call(session, plant.url, csrf, "tags.forces")
        assert status == 200 and [(f["tag"], f["value"], f["by"]) for f in forces] == [("limit", 42.5, "hmi:engineer@127.0.0.1")]
        # A forced tag refuses every client's write, the HMI's included.
        async with session.post(plant.url + "api/write", json={"tag": "limit", "value": 1}, headers={"X-CSRF-Token": csrf}) as response:
            assert response.status == 422 and (await response.json())["results"][0]["rule"] == "forced"
        status, result = await call(session, plant.url, csrf, "tags.unforce", {"tag": "limit", "restore": True})
        assert status == 200 and result == "limit unforced and restored from the next cycle"
        update = await receive_until(ws, lambda m: m["type"] == "update" and "limit" in m["values"])
        assert "forced" not in update and update["values"]["limit"] == 0.0  # restored to its value before the force
    call_record = plant.calls[-1]
    assert (call_record.command, call_record.accepted, call_record.origin.source, call_record.origin.user) == ("tags.unforce", True, "hmi", "engineer")


async def test_operators_viewers_and_visitors_are_refused_by_the_role_check_and_it_is_reported(plant: Plant) -> None:
    for user in ("operator", "viewer", None):
        async with http_client() as session:
            csrf = await http_login(session, plant.url, user) if user else None
            before = len(plant.calls)
            status, body = await call(session, plant.url, csrf, "tags.force", {"tag": "limit", "value": 7})
            role = user or "viewer"  # a visitor who has not logged in is told to, and reported with the anonymous role
            refusal = f"role {role} may not force tags" if user else "log in to force tags"
            assert status == 403 and body == {"error": refusal}, (user, body)
            assert not plant.db["limit"].forced
            refused = plant.calls[before:]
            assert [(c.command, c.accepted, c.origin.role.value if c.origin.role else None) for c in refused] == [("tags.force", False, role)]
            # Reading is every role's: the list of forces, the programs.
            status, forces = await call(session, plant.url, csrf, "tags.forces")
            assert status == 200 and forces == []
            async with session.get(plant.url + "api/commands") as response:
                listed = {row["name"]: row["allowed"] for row in (await response.json())["commands"]}
            assert listed["tags.forces"] and listed["programs.list"] and not listed["tags.force"] and not listed["programs.apply"]


async def test_a_call_without_the_sessions_csrf_token_is_refused(plant: Plant) -> None:
    async with http_client() as session:
        await http_login(session, plant.url, "engineer")
        before = len(plant.calls)
        status, body = await call(session, plant.url, None, "tags.force", {"tag": "limit", "value": 7})
        assert status == 403 and "CSRF" in body["error"]
        assert not plant.db["limit"].forced  # never reached the command, but the refusal is reported (audit trail)
        assert [(c.command, c.accepted, c.detail) for c in plant.calls[before:]] == [("tags.force", False, body["error"])]
        async with session.post(plant.url + "api/commands/tags.forces", data="{}", headers={"Origin": "http://evil.example"}) as response:
            assert response.status == 403  # another site's page: refused by the Origin check first


async def test_refusals_come_back_in_the_runtimes_words(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "engineer")
        status, body = await call(session, plant.url, csrf, "tags.force", {"tag": "limit", "value": 1000})
        assert status == 422 and body == {"error": "limit: out of range: 1000.0 is above the maximum 100"}
        status, body = await call(session, plant.url, csrf, "tags.unforce", {"tag": "limit"})
        assert status == 422 and body == {"error": "limit is not forced"}
        status, body = await call(session, plant.url, csrf, "tags.forse", {"tag": "limit"})
        assert status == 404 and body["error"] == "no such command 'tags.forse' (did you mean 'tags.force'?)"
        status, body = await call(session, plant.url, csrf, "tags.force", {"tag": "limit", "value": 1, "colour": "red"})
        assert status == 422 and body["error"] == "tags.force: unknown argument 'colour'; it takes: tag, value"
        async with session.post(plant.url + "api/commands/tags.force", data="[1, 2]", headers={"X-CSRF-Token": csrf}) as response:
            assert response.status == 400 and "JSON object" in (await response.json())["error"]


async def test_an_engineer_stops_and_starts_a_program(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "engineer")
        counter = plant.db.value("counter")
        status, result = await call(session, plant.url, csrf, "programs.stop", {"program": "count"})
        assert status == 200 and result.startswith("stopped program count")
        stopped = plant.db.value("counter")
        assert plant.runtime.program("count").state.value == "STOPPED" and stopped >= counter
        status, programs = await call(session, plant.url, csrf, "programs.list")
        assert next(p for p in programs if p["name"] == "count")["actions"] == ["start", "restart"]
        status, result = await call(session, plant.url, csrf, "programs.start", {"program": "count"})
        assert status == 200 and result.startswith("started program count")
        await wait_until(lambda: plant.db.value("counter") > stopped + 3, message="counting again")


async def test_an_online_change_that_needs_a_restart_is_refused_with_its_details(plant: Plant) -> None:
    path = plant.runtime.config.path
    original = path.read_text()
    path.write_text(original.replace("  flag:    {type: bool}\n", "  flag:    {type: bool}\n  extra:   {type: bool}\n"))
    try:
        async with http_client() as session:
            csrf = await http_login(session, plant.url, "engineer")
            status, body = await call(session, plant.url, csrf, "programs.apply", {"check": True})
    finally:
        path.write_text(original)
    assert status == 422 and body["error"].startswith("online change refused, nothing applied: changes that need a restart")
    assert body["details"]["applied"] is False and body["details"]["needs_restart"] == ["tag 'extra' added"]
    assert "extra" not in plant.db


async def test_the_audit_page_exports_csv_for_engineers_only(tmp_path: Path) -> None:
    from softplc.adapters.audit.recorder import AuditRecorder
    from softplc.storage.audit.settings import AuditSettings

    plant = await start_plant(tmp_path, start=False)
    plant.runtime.adapters.insert(0, AuditRecorder(AuditSettings(section={"flush_period": "50ms"}), "hmi test plant"))
    await plant.runtime.start()
    try:
        async with http_client() as session:
            csrf = await http_login(session, plant.url, "operator")
            async with session.post(plant.url + "api/write", json={"tag": "limit", "value": 12.5}, headers={"X-CSRF-Token": csrf}) as response:
                assert response.status == 200
            async with session.get(plant.url + "api/audit.csv?tag=limit") as response:
                assert response.status == 403 and "may not read the audit trail" in (await response.json())["error"]
        async with http_client() as session:
            await http_login(session, plant.url, "engineer")
            async with session.get(plant.url + "api/audit.csv?tag=limit&source=hmi") as response:
                assert response.status == 200 and response.content_type == "text/csv"
                assert response.headers["Content-Disposition"].startswith("attachment; filename=\"audit-")
                rows = list(csv.DictReader(io.StringIO(await response.text())))
        assert [(r["kind"], r["name"], r["user"], r["role"], r["new"], r["accepted"]) for r in rows] == [
            ("write", "limit", "operator", "operator", "12.5", "True")]
    finally:
        await plant.stop()
