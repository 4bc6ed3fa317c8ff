"""The HMI's door to the runtime's commands, the alarm journal's CSV download and alarms on the live channel.

Real HTTP and WebSockets (aiohttp client) against a real runtime with alarms and a historian,
one runtime for the module.
"""

from __future__ import annotations

import asyncio
import csv
import enum
import io
import json
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from hmi_supervisory_support import start_supervisory_plant
from hmi_support import Plant, http_client, http_login, post_command, receive_until, strict_json, wait_until

from softplc.core.commands import CommandCall, Permission

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_supervisory_plant(tmp_path_factory.mktemp("hmi-commands"), modbus=False)
    plant.calls: list[CommandCall] = []  # type: ignore[misc]
    plant.runtime.commands.on_call(plant.calls.append)
    yield plant
    await plant.stop()


def state(plant: Plant, alarm: str) -> str:
    return plant.adapters["alarms"].engine.get(alarm).state.value


async def raise_alarm(plant: Plant, task: str = "t01", items: int = 95) -> None:
    plant.drive(**{f"{task}_iBM": items})
    await wait_until(lambda: state(plant, f"{task}_input_full") == "unacknowledged", message=f"{task}_input_full active")


async def clear_alarms(plant: Plant) -> None:
    plant.drive(t01_iBM=0, t02_iBM=0, flag=False)
    await wait_until(lambda: not plant.adapters["alarms"].engine.active_count, message="alarms cleared")
    await plant.runtime.commands.call("alarms.acknowledge_all", {}, "test")


async def test_an_operator_acknowledges_through_the_door_and_the_journal_says_who(plant: Plant) -> None:
    await raise_alarm(plant)
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full", "comment": "on it"}, csrf)
        assert status == 200, body
        assert body["ok"] is True and body["result"] == "acknowledged t01_input_full (now acknowledged)"
        assert isinstance(body["time"], float)
        assert state(plant, "t01_input_full") == "acknowledged"
        status, body = await post_command(session, plant.url, "alarms.journal", {"alarm": "t01_input_full", "transition": "acknowledged", "limit": 1})
        assert status == 200
        (row,) = body["result"]
        assert (row["user"], row["role"], row["origin"], row["comment"]) == ("operator", "operator", "hmi:operator@127.0.0.1", "on it")
    call = plant.calls[-1]
    assert (call.command, call.accepted, call.origin.source, call.origin.user) == ("alarms.acknowledge", True, "hmi", "operator")
    await clear_alarms(plant)


async def test_a_viewer_is_refused_with_403_and_the_refusal_is_reported(plant: Plant) -> None:
    await raise_alarm(plant)
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "viewer")
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full"}, csrf)
        assert status == 403
        assert body == {"ok": False, "command": "alarms.acknowledge", "error": "role viewer may not acknowledge alarms"}
        status, body = await post_command(session, plant.url, "alarms.shelve", {"alarm": "t01_input_full", "reason": "x", "duration": 60}, csrf)
        assert status == 403 and body["error"] == "role viewer may not shelve alarms"
        # Reading is open to a viewer.
        status, body = await post_command(session, plant.url, "alarms.list", {"state": "unacknowledged"})
        assert status == 200 and [alarm["name"] for alarm in body["result"]] == ["t01_input_full"]
    assert state(plant, "t01_input_full") == "unacknowledged"
    refused = [call for call in plant.calls if call.origin.user == "viewer"]
    assert [(call.command, call.accepted) for call in refused[-2:]] == [("alarms.acknowledge", False), ("alarms.shelve", False)]
    await clear_alarms(plant)


async def test_state_changing_commands_need_a_login_and_the_csrf_token(plant: Plant) -> None:
    await raise_alarm(plant)
    async with http_client() as session:
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full"})
        assert status == 403 and body["error"] == "log in to acknowledge alarms"  # the anonymous viewer
        csrf = await http_login(session, plant.url, "operator")
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full"})
        assert status == 403 and body["error"] == "missing or wrong CSRF token (X-CSRF-Token)"
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full"}, "forged-token")
        assert status == 403 and "CSRF" in body["error"]
        status, _ = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full"}, csrf, Origin="http://evil.example")
        assert status == 403  # another site's page, even with the token
        assert state(plant, "t01_input_full") == "unacknowledged"
    async with http_client() as session:  # commands that only read need no token: the anonymous viewer may look
        status, body = await post_command(session, plant.url, "alarms.summary")
        assert status == 200 and body["result"]["unacknowledged"] == 1
    await clear_alarms(plant)


async def test_unknown_commands_bad_arguments_and_other_refusals_say_what_is_wrong(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        status, body = await post_command(session, plant.url, "alarms.acknowlege", {"alarm": "x"}, csrf)
        assert status == 404 and body["error"] == "no such command 'alarms.acknowlege' (did you mean 'alarms.acknowledge'?)"
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_full"}, csrf)
        assert status == 422 and body["error"] == "alarm t01_input_full needs no acknowledgement: it is normal"
        status, body = await post_command(session, plant.url, "alarms.acknowledge", {"alarm": "t01_input_ful"}, csrf)
        assert status == 422 and body["error"] == "no alarm named 't01_input_ful' (did you mean 't01_input_full'?)"
        status, body = await post_command(session, plant.url, "alarms.shelve", {"alarm": "t01_input_full", "reason": " ", "duration": 60}, csrf)
        assert status == 422 and body["error"] == "shelving t01_input_full needs a reason"
        status, body = await post_command(session, plant.url, "alarms.list", {"sate": "all"})
        assert status == 422 and body["error"].startswith("alarms.list: unknown argument 'sate'")
        status, body = await post_command(session, plant.url, "alarms.list", ["all"])
        assert status == 400 and body["error"] == 'the arguments are a JSON object ({"name": value, ...}), not an array'
        async with session.post(plant.url + "api/commands/alarms.list", data=b"{oops", headers={"X-CSRF-Token": csrf}) as response:
            assert response.status == 400
            assert (await response.json())["error"].startswith("the body is not JSON")
        async with session.post(plant.url + "api/commands/alarms.list", data=b"\xff\xfe", headers={"X-CSRF-Token": csrf}) as response:
            assert response.status == 400


class Colour(enum.Enum):
    RED = "red"


@dataclass
class Point:
    x: float
    colour: Colour


async def test_results_are_strict_json_whatever_a_command_returns(plant: Plant) -> None:
    def odd(arguments: Any, origin: Any) -> Any:
        return {"nan": math.nan, "inf": [math.inf, -math.inf], "tuple": (1, 2.5), "enum": Colour.RED, "point": Point(math.nan, Colour.RED),
                "set": {"only"}, Colour.RED: "enum key", "path": Path("/plant/x")}

    undo = plant.runtime.commands.register("test.odd", odd, permission=Permission.VIEW)
    try:
        async with http_client() as session:
            status, body = await post_command(session, plant.url, "test.odd")
        assert status == 200
        assert body["result"] == {"nan": "NaN", "inf": ["Infinity", "-Infinity"], "tuple": [1, 2.5], "enum": "red",
                                  "point": {"x": "NaN", "colour": "red"}, "set": ["only"], "red": "enum key", "path": "/plant/x"}
    finally:
        undo()


async def test_the_list_of_commands_says_what_the_role_may_call(plant: Plant) -> None:
    async with http_client() as session:
        async with session.get(plant.url + "api/commands") as response:
            anonymous = {row["name"]: row for row in (await response.json())["commands"]}
        await http_login(session, plant.url, "operator")
        async with session.get(plant.url + "api/commands") as response:
            operator = {row["name"]: row["allowed"] for row in (await response.json())["commands"]}
    assert anonymous["alarms.acknowledge"]["allowed"] is False and anonymous["alarms.list"]["allowed"] is True
    assert anonymous["alarms.shelve"]["arguments"]["reason"] == "why (required)"
    assert operator["alarms.acknowledge"] is True and operator["alarms.out_of_service"] is False
    assert operator["history.plot"] is True


async def test_the_journal_downloads_as_csv_with_its_filters(plant: Plant) -> None:
    await raise_alarm(plant, "t02")
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        status, _ = await post_command(session, plant.url, "alarms.comment", {"alarm": "t02_input_full", "comment": "a, \"quoted\" note"}, csrf)
        assert status == 200
        async with session.get(plant.url + "api/alarms/journal.csv", params={"alarm": "t02*", "transition": "commented,acknowledged"}) as response:
            assert response.status == 200
            assert response.headers["Content-Type"] == "text/csv; charset=utf-8"
            assert response.headers["Content-Disposition"].startswith('attachment; filename="alarm-journal-')
            rows = list(csv.DictReader(io.StringIO(await response.text())))
        assert rows and {row["alarm"] for row in rows} == {"t02_input_full"}
        assert rows[0]["transition"] == "commented" and rows[0]["comment"] == 'a, "quoted" note' and rows[0]["user"] == "operator"
        assert rows[0]["time_utc"].endswith("Z")
        async with session.get(plant.url + "api/alarms/journal.csv", params={"since": "yesterday"}) as response:
            assert response.status == 400
            assert "ISO 8601" in (await response.json())["error"]
    await clear_alarms(plant)


async def test_history_reads_go_through_the_door(plant: Plant) -> None:
    plant.drive(speed=1.5)
    await asyncio.sleep(0.3)
    plant.drive(speed=2.5)
    wall = plant.runtime.clock.wall

    async def plotted() -> list[float]:
        async with http_client() as session:
            status, body = await post_command(session, plant.url, "history.plot", {"tag": "speed", "start": wall() - 60, "end": wall() + 1})
        assert status == 200, body
        return [sample["value"] for sample in body["result"]["samples"]]

    deadline = time.monotonic() + 5
    while 2.5 not in await plotted():
        assert time.monotonic() < deadline, "recorded values not readable"
        await asyncio.sleep(0.1)
    assert {1.5, 2.5} <= set(await plotted())
    async with http_client() as session:
        status, body = await post_command(session, plant.url, "history.plot", {"tag": "nope", "start": 0, "end": 1})
    assert status == 422 and "nope" in body["error"]


async def test_the_live_channel_sends_an_alarm_snapshot_then_the_changes(plant: Plant) -> None:
    await raise_alarm(plant)
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_str(json.dumps({"type": "alarms", "on": True}))
        snapshot = await receive_until(ws, "alarms")
        assert snapshot["snapshot"] is True
        assert [alarm["name"] for alarm in snapshot["alarms"]] == ["t01_input_full"]
        assert snapshot["summary"]["most_severe_unacknowledged"]["name"] == "t01_input_full"
        plant.drive(t01_iBM=100)  # hi → hihi: re-alarmed as critical
        update = await receive_until(ws, "alarms")
        assert "snapshot" not in update
        assert [(t["alarm"], t["transition"], t["state"], t["priority"]) for t in update["transitions"]] == [
            ("t01_input_full", "realarmed", "unacknowledged", "critical")]
        assert update["alarms"][-1]["priority"] == "critical" and update["summary"]["highest_priority"] == 4
        await clear_alarms(plant)
        names: dict[str, str] = {}
        while names.get("t01_input_full") != "normal":
            update = await receive_until(ws, "alarms")
            names.update({alarm["name"]: alarm["state"] for alarm in update["alarms"]})
        assert update["summary"]["active"] == 0


async def test_a_flood_of_transitions_comes_rate_limited_and_complete(plant: Plant) -> None:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_str(json.dumps({"type": "alarms", "on": True}))
        await receive_until(ws, "alarms")
        started = time.monotonic()
        for index in range(60):  # a transition every ~10 ms (comments are journaled and published at once)
            await plant.runtime.commands.call("alarms.comment", {"alarm": "flag_on", "comment": f"note {index}"}, "test")
            await asyncio.sleep(0.01)
        messages, comments = 0, []
        while len(comments) < 60:
            update = strict_json((await ws.receive(timeout=5)).data)
            if update["type"] != "alarms":
                continue
            messages += 1
            comments.extend(t["comment"] for t in update["transitions"] if t["transition"] == "commented")
            assert update["dropped"] == 0
        elapsed = time.monotonic() - started
        assert comments == [f"note {index}" for index in range(60)]  # every one, in order
        assert messages <= elapsed * plant.hmi.settings.max_update_rate + 2, (messages, elapsed)


async def test_a_runtime_without_alarms_has_no_alarm_pages_and_says_so_on_the_live_channel(tmp_path: Path) -> None:
    from hmi_support import start_plant

    plain = await start_plant(tmp_path)
    try:
        assert [page.id for page in plain.hmi.shell.pages if page.id in ("alarms", "journal", "trends")] == []
        async with http_client() as session:
            async with session.get(plain.url + "api/session") as response:
                assert [banner for banner in (await response.json())["banners"] if "alarm" in banner] == []  # the forced banner stays
            async with session.ws_connect(plain.url + "api/live") as ws:
                await ws.send_str(json.dumps({"type": "alarms", "on": True}))
                assert (await receive_until(ws, "error"))["message"] == "this runtime has no alarms"
            async with session.get(plain.url + "api/alarms/journal.csv") as response:
                assert response.status == 404
    finally:
        await plain.stop()
