"""The HMI against a hostile client (issue 21): floods of long names, deeply nested JSON, cross-origin writes.

Over real HTTP and WebSockets (aiohttp client) against a running runtime; the audit trail's
entries are read from its store.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
import pytest_asyncio
from audit_support import entries, running
from hmi_support import Plant, http_client, http_login, receive_until, start_plant

from softplc.core.tagdb import Rule, WriteEvent

pytestmark = pytest.mark.asyncio(loop_scope="module")

LONG = 900  # characters of each name in the reported attack
DEEP = 100_000  # levels of nesting in the reported attack


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_plant(tmp_path_factory.mktemp("hmi-hardening"))
    plant.writes: list[WriteEvent] = []  # type: ignore[misc]
    plant.db.on_write(plant.writes.extend)
    yield plant
    await plant.stop()


def long_names(count: int) -> list[dict[str, Any]]:
    return [{"tag": f"{index:04d}" + "x" * (LONG - 4), "value": 1} for index in range(count)]


async def post_writes(session: aiohttp.ClientSession, url: str, csrf: str | None, writes: list[dict[str, Any]],
                      **headers: str) -> tuple[int, dict[str, Any]]:
    sent = {"X-CSRF-Token": csrf} if csrf else {}
    async with session.post(url + "api/write", json={"writes": writes}, headers={**sent, **headers}) as response:
        return response.status, await response.json()


# -- item 3: one request of 1,000 long unknown names ----------------------------------------------

async def test_a_viewers_write_is_refused_for_its_role_before_any_name_is_looked_up(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "viewer")
        del plant.writes[:]
        status, body = await post_writes(session, plant.url, csrf, long_names(1000))
    assert status == 403, body
    results = body["results"]
    assert len(results) == 1000
    assert {result["rule"] for result in results} == {"access denied"}
    assert not any("did you mean" in result["detail"] for result in results)
    assert all(len(result["tag"]) < 300 for result in results)  # a name is echoed clipped
    # Every item still reaches the write listeners (the audit trail), its name clipped.
    refused = [event for event in plant.writes if event.origin.user == "viewer"]
    assert len(refused) == 1000 and all(event.rule is Rule.ACCESS_DENIED for event in refused)
    assert max(len(event.tag) for event in refused) < 300


async def test_an_operators_long_unknown_names_are_refused_without_a_search(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        status, body = await post_writes(session, plant.url, csrf, long_names(1000))
    assert status == 422
    assert {result["rule"] for result in body["results"]} == {"unknown tag"}
    assert not any("did you mean" in result["detail"] for result in body["results"])
    assert all(len(result["tag"]) < 300 for result in body["results"])


async def test_did_you_mean_is_looked_up_for_a_few_names_of_a_request_only(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        status, body = await post_writes(session, plant.url, csrf, [{"tag": f"limt{index}", "value": 1} for index in range(1000)])
    assert status == 422
    hinted = [result for result in body["results"] if "did you mean 'limit'" in result["detail"]]
    assert 1 <= len(hinted) <= 5, len(hinted)  # the first few names, not a search of every tag for each of 1,000
    assert all(result["rule"] == "unknown tag" for result in body["results"])


async def test_a_refused_entry_and_its_log_line_hold_a_clipped_name_and_value(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    async with running(tmp_path) as runtime:
        url = next(adapter for adapter in runtime.adapters if adapter.name == "hmi").url
        async with http_client() as session:
            csrf = await http_login(session, url, "operator")
            status, _ = await post_writes(session, url, csrf, [*long_names(3), {"tag": "name", "value": 5},
                                                               {"tag": "level", "value": "y" * 100_000}])
        assert status == 422
        refused = await entries(runtime, accepted=False)
    assert len(refused) == 5
    for entry in refused:
        assert len(entry.name) < 300 and len(entry.tag) < 300, entry.name
        assert len(json.dumps(entry.new)) < 600 and len(entry.detail) < 600
    assert refused[-1].name == "level" and refused[-1].new.startswith('"yyy') and "characters)" in refused[-1].new
    lines = [record.getMessage() for record in caplog.records if record.name.startswith("softplc")]
    assert lines and max(len(line) for line in lines) < 1000, max(lines, key=len)[:200]


# -- item 4: JSON nested 100,000 deep -------------------------------------------------------------

def deep_json(key: str | None = None) -> str:
    nested = "[" * DEEP + "]" * DEEP
    return json.dumps({key: "@"}).replace('"@"', nested) if key else nested


async def test_deeply_nested_json_is_a_bad_request_not_a_server_error(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "engineer")
        headers = {"Content-Type": "application/json", "X-CSRF-Token": csrf}
        for path, body in (("api/write", deep_json()), ("api/write", deep_json("writes")), ("api/write", deep_json("value")),
                           ("api/commands/tags.force", deep_json()), ("api/commands/tags.force", deep_json("tag")),
                           ("api/login", deep_json())):
            async with session.post(plant.url + path, data=body, headers=headers) as response:
                text = await response.text()
                assert response.status == 400, (path, body[:20], response.status, text[:300])
                assert "Traceback" not in text and "nested too deeply" in json.loads(text)["error"], text[:300]


async def test_deeply_nested_json_on_the_live_channel_gets_an_error_and_the_connection_stays(plant: Plant) -> None:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await receive_until(ws, "hello")
        for text in (deep_json(), json.dumps({"type": "subscribe", "items": "@"}).replace('"@"', "[" * DEEP + "]" * DEEP)):
            await ws.send_str(text)
            error = await receive_until(ws, "error")
            assert "nested too deeply" in error["message"]
        await ws.send_json({"type": "ping"})
        await receive_until(ws, "pong")
        assert not ws.closed


# -- item 14: writes refused by the Origin check ----------------------------------------------------

async def test_a_cross_origin_write_is_reported_and_logged(plant: Plant, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        del plant.writes[:]
        status, body = await post_writes(session, plant.url, csrf, [{"tag": "limit", "value": 4.0}], Origin="http://evil.example")
        assert status == 403 and "cross-origin" in body["error"]
        for _ in range(20):  # a flood is logged once, not twenty times
            await post_writes(session, plant.url, csrf, [{"tag": "limit", "value": 5.0}], Origin="http://evil.example")
    event = plant.writes[0]
    assert event.tag == "limit" and event.new == 4.0 and event.rule is Rule.INVALID_REQUEST
    assert "http://evil.example" in event.detail and event.origin.source == "hmi"
    assert len(plant.writes) == 21
    # A flood is not logged twenty-one times: one line for the address (its later refusals are
    # summarised), and the operator's write log's burst of lines (writelog.py; fewer when the
    # operator's budget of this interval was spent by earlier tests on this module's plant).
    lines = [record.getMessage() for record in caplog.records if "evil.example" in record.getMessage()]
    by_address = [line for line in lines if line.startswith("HMI: POST /api/write from")]
    by_user = [line for line in lines if line.startswith("HMI write by")]
    assert len(by_address) == 1 and "refused" in by_address[0], lines
    assert len(by_user) <= plant.hmi.writelog.burst and len(lines) == len(by_address) + len(by_user), lines


async def test_a_cross_origin_command_is_reported(plant: Plant) -> None:
    calls: list[Any] = []
    undo = plant.runtime.commands.on_call(calls.append)
    try:
        async with http_client() as session:
            csrf = await http_login(session, plant.url, "engineer")
            async with session.post(plant.url + "api/commands/tags.force", json={"tag": "limit", "value": 7},
                                    headers={"X-CSRF-Token": csrf, "Origin": "http://evil.example"}) as response:
                assert response.status == 403
    finally:
        undo()
    assert len(calls) == 1 and calls[0].command == "tags.force" and not calls[0].accepted
    assert "evil.example" in calls[0].detail and calls[0].arguments == {"tag": "limit", "value": 7}
    await asyncio.sleep(0)


# -- item 5: live connections per address ---------------------------------------------------------

async def test_one_address_cannot_take_every_live_connection(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    plant = await start_plant(tmp_path, max_clients=5, max_clients_per_address=2)
    try:
        async with http_client() as visitor, http_client() as operator, http_client() as engineer:
            held = [await visitor.ws_connect(plant.url + "api/live") for _ in range(2)]
            for ws in held:
                await receive_until(ws, "hello")
            for _ in range(5):  # a third visitor's tab from the same address is told why, clearly, every time
                async with visitor.ws_connect(plant.url + "api/live") as refused:
                    message = await refused.receive(timeout=5)
                    assert message.type is aiohttp.WSMsgType.CLOSE and refused.close_code == 1013
                    assert message.extra == "too many live connections from 127.0.0.1 (at most 2 per address without a login): close other tabs"
            # A login counts on its own: the visitors' flood does not lock out an operator.
            await http_login(operator, plant.url, "operator")
            mine = [await operator.ws_connect(plant.url + "api/live") for _ in range(2)]
            for ws in mine:
                assert (await receive_until(ws, "hello"))["role"] == "operator"
            # The runtime's own limit (max_clients: 5) is said as clearly.
            await http_login(engineer, plant.url, "engineer")
            async with engineer.ws_connect(plant.url + "api/live") as other:
                await receive_until(other, "hello")
                async with visitor.ws_connect(plant.url + "api/live") as refused:
                    message = await refused.receive(timeout=5)
                    assert refused.close_code == 1013 and "at most 5 live connections" in message.extra
            for ws in [*held, *mine]:
                await ws.close()
        lines = [record.getMessage() for record in caplog.records if "live connection from" in record.getMessage()]
        assert 1 <= len(lines) <= 2 and "refused: too many live connections" in lines[0], lines  # rate-limited per address
    finally:
        await plant.stop()


# -- item 9: expressions current in every snapshot ------------------------------------------------

async def snapshot_of(plant: Plant, items: list[str]) -> dict[str, Any]:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_json({"type": "subscribe", "items": items})
        return (await receive_until(ws, "snapshot"))["values"]


async def test_an_expression_is_current_in_a_snapshot_after_changes_nobody_watched(plant: Plant) -> None:
    from hmi_support import wait_until

    alarm, running = "=t01_iBL >= 80", "=_sys.state == 'RUNNING'"
    await wait_until(lambda: plant.db.value("_sys.state") == "RUNNING", message="the runtime running")
    for items, level in ((90, 90.0), (10, 10.0), (85, 85.0)):
        await wait_until(lambda: not plant.hmi.hub.groups, message="no browser watching")
        plant.drive(t01_iBM=items)
        await wait_until(lambda: plant.db.value("t01_iBL") == level, message=f"level {level}")
        await asyncio.sleep(0.05)  # the change has gone past the live channel (nobody watching)
        values = await snapshot_of(plant, [alarm, running, "t01_iBL"])
        assert values["t01_iBL"] == level
        assert values[alarm] is (level >= 80), (level, values)
        assert values[running] is True, values


async def test_deeply_nested_json_to_the_opc_ua_commands_door_is_an_invalid_argument(tmp_path: Path) -> None:
    """The same commands through OPC UA (Objects/Commands.Call, JSON arguments): BadInvalidArgument, not BadInternalError."""
    from asyncua import ua
    from audit_support import opcua_client

    async with running(tmp_path) as runtime:
        async with opcua_client(runtime, "engineer") as client:
            ns = await client.get_namespace_index("urn:softplc:tags")
            door = client.get_node(ua.NodeId("Commands", ns))
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await door.call_method(ua.NodeId("Commands.Call", ns), "tags.force", "[" * DEEP + "]" * DEEP)
    assert ua.StatusCode(refused.value.code).name == "BadInvalidArgument"
