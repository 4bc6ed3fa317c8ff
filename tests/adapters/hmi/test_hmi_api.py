"""The HMI's JSON API and live channel over real HTTP and WebSockets (aiohttp client), one runtime per module.

Login and roles, CSRF and Origin refusals, the Host check, writes with the core's rules and
messages, every write reaching the write listeners, WebSocket origin refusal, snapshots, the
rate limit and security headers.
"""

from __future__ import annotations

import json
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
import pytest_asyncio
from hmi_support import DRIVER, PASSWORDS, Plant, http_client, http_login, receive_until, start_plant, wait_until

from softplc.core.tagdb import Rule, WriteEvent, WriteRejected
from softplc.core.tags import Quality

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_plant(tmp_path_factory.mktemp("hmi-api"))
    plant.writes: list[WriteEvent] = []  # type: ignore[misc]
    plant.db.on_write(plant.writes.extend)
    yield plant
    await plant.stop()


async def write(session: aiohttp.ClientSession, url: str, csrf: str | None, tag: str, value: Any, **headers: str) -> tuple[int, dict[str, Any]]:
    sent = {"X-CSRF-Token": csrf} if csrf else {}
    async with session.post(url + "api/write", json={"tag": tag, "value": value}, headers={**sent, **headers}) as response:
        return response.status, await response.json()


async def test_login_sets_an_httponly_samesite_cookie_and_the_role(plant: Plant) -> None:
    async with http_client() as session:
        async with session.post(plant.url + "api/login", json={"user": "operator", "password": PASSWORDS["operator"]}) as response:
            assert response.status == 200
            body = await response.json()
            cookie = response.headers["Set-Cookie"]
        assert body["role"] == "operator" and body["csrf"]
        assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/" in cookie
        assert cookie.startswith(f"softplc_hmi_{plant.hmi.port}=")
        async with session.get(plant.url + "api/session") as response:
            me = await response.json()
        assert me["user"] == "operator" and me["role"] == "operator" and me["csrf"] == body["csrf"]


async def test_wrong_password_is_refused_without_saying_which_part_was_wrong(plant: Plant) -> None:
    async with http_client() as session:
        for user in ("operator", "nobody"):
            async with session.post(plant.url + "api/login", json={"user": user, "password": "wrong-password"}) as response:
                assert response.status == 401
                assert (await response.json())["error"].startswith("wrong user name or password")


async def test_login_needs_json_so_a_form_of_another_site_cannot_post_it(plant: Plant) -> None:
    async with http_client() as session:
        async with session.post(plant.url + "api/login", data={"user": "operator", "password": PASSWORDS["operator"]}) as response:
            assert response.status == 415


async def test_a_write_without_the_csrf_token_is_refused_and_reported(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        before = plant.db.value("limit")
        for token in (None, "not-the-token"):
            status, body = await write(session, plant.url, token, "limit", 55.0)
            assert status == 403
            assert body["results"][0]["rule"] == Rule.INVALID_REQUEST.value
            assert "CSRF" in body["error"]
        assert plant.writes[-1].rule is Rule.INVALID_REQUEST and plant.writes[-1].origin.user == "operator"
        status, body = await write(session, plant.url, csrf, "limit", 55.0)
        assert status == 200 and body["ok"] and body["results"][0]["old"] == before
        await wait_until(lambda: plant.db.value("limit") == 55.0, message="the write applied")
        event = plant.writes[-1]
        assert event.accepted and event.origin.source == "hmi" and event.origin.user == "operator" and event.new == 55.0


async def test_roles_decide_what_may_be_written_with_the_cores_rules_and_messages(plant: Plant) -> None:
    cases = [
        ("viewer", "limit", 1.0, "access denied"),
        ("operator", "limit", 2.0, None),
        ("operator", "counter", 5, "read-only"),
        ("engineer", "counter", 5, None),
        ("engineer", "_sys.state", "RUNNING", "read-only"),
        ("operator", "limit", 1000.0, "out of range"),
        ("operator", "flag", "yes", "type mismatch"),
        ("operator", "limt", 1.0, "unknown tag"),
    ]
    for user, tag, value, rule in cases:
        async with http_client() as session:
            csrf = await http_login(session, plant.url, user)
            status, body = await write(session, plant.url, csrf, tag, value)
        result = body["results"][0]
        if rule is None:
            assert status == 200 and result["ok"], (user, tag, body)
        else:  # a role that may write nothing is refused the whole request (403), before any tag is looked at
            assert status == (403 if user == "viewer" else 422) and result["rule"] == rule, (user, tag, body)
    # The messages are the tag database's own (the same as OPC UA and Modbus give).
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        _, body = await write(session, plant.url, csrf, "limit", 1000.0)
        with pytest.raises(WriteRejected) as core:
            plant.db.validate("limit", 1000.0)
        assert body["results"][0]["detail"] == core.value.detail == "1000.0 is above the maximum 100"
        _, body = await write(session, plant.url, csrf, "limt", 1.0)
        assert "did you mean 'limit'" in body["results"][0]["detail"]


async def test_an_anonymous_visitor_cannot_write_and_the_attempt_is_reported(plant: Plant) -> None:
    async with http_client() as session:
        status, body = await write(session, plant.url, None, "limit", 3.0)
    assert status == 403 and body["results"][0]["rule"] == "access denied"
    event = plant.writes[-1]
    assert event.tag == "limit" and event.rule is Rule.ACCESS_DENIED and event.origin.source == "hmi"


async def test_a_write_from_another_origin_is_refused(plant: Plant) -> None:
    async with http_client() as session:
        csrf = await http_login(session, plant.url, "operator")
        status, body = await write(session, plant.url, csrf, "limit", 4.0, Origin="http://evil.example")
        assert status == 403 and "cross-origin" in body["error"]
        status, _ = await write(session, plant.url, csrf, "limit", 4.0, Origin=plant.url.rstrip("/"))
        assert status == 200


async def test_a_rebound_host_name_is_refused(plant: Plant) -> None:
    """DNS rebinding: evil.example made to resolve to 127.0.0.1 must not be served."""
    async with http_client() as session:
        async with session.get(plant.url + "api/tags", headers={"Host": f"evil.example:{plant.hmi.port}"}) as response:
            assert response.status == 421
        async with session.get(plant.url + "api/session", headers={"Host": f"localhost:{plant.hmi.port}"}) as response:
            assert response.status == 200


async def test_tags_api_lists_declarations_values_and_what_the_role_may_write(plant: Plant) -> None:
    async with http_client() as session:
        async with session.get(plant.url + "api/tags") as response:
            anonymous = {tag["name"]: tag for tag in (await response.json())["tags"]}
        await http_login(session, plant.url, "operator")
        async with session.get(plant.url + "api/tags?group=Tasks&q=ibm") as response:
            body = await response.json()
        async with session.get(plant.url + "api/tags/limit") as response:
            limit = await response.json()
        async with session.get(plant.url + "api/tags/limt") as response:
            assert response.status == 404 and "did you mean 'limit'" in (await response.json())["error"]
    assert len(anonymous) == len(plant.db) and not any(tag["writable"] for tag in anonymous.values())
    assert [tag["name"] for tag in body["tags"]] == ["t01_iBM", "t02_iBM"]
    assert limit["writable"] and limit["unit"] == "bar" and limit["min"] == 0 and limit["max"] == 100
    assert limit["quality"] == "good" and limit["timestamp"] > 0
    assert anonymous["note"]["description"].startswith("<script>")  # data; the page shows it as text


async def test_every_answer_carries_the_security_headers(plant: Plant) -> None:
    async with http_client() as session:
        for path in ("", "static/js/main.js", "api/session", "api/nothing"):
            async with session.get(plant.url + path) as response:
                policy = response.headers["Content-Security-Policy"]
                assert "script-src 'self'" in policy and "unsafe-inline" not in policy and "frame-ancestors 'none'" in policy
                assert response.headers["X-Content-Type-Options"] == "nosniff"


async def test_the_live_channel_refuses_another_origin(plant: Plant) -> None:
    async with http_client() as session:
        with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
            await session.ws_connect(plant.url + "api/live", origin="http://evil.example")
        assert refused.value.status == 403
        async with session.ws_connect(plant.url + "api/live", origin=plant.url.rstrip("/")) as ws:
            hello = json.loads((await ws.receive(timeout=5)).data)
            assert hello["type"] == "hello" and hello["role"] == "viewer"


async def test_a_subscription_gets_a_snapshot_then_only_changes_at_most_rate_per_second(plant: Plant) -> None:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_json({"type": "subscribe", "items": ["counter", "limit", "=t01_iBM + t02_iBM", "no_such_tag"]})
        unknown = await receive_until(ws, "unknown")
        assert unknown["items"] == ["no_such_tag"]
        snapshot = await receive_until(ws, "snapshot")
        assert set(snapshot["values"]) == {"counter", "limit", "=t01_iBM + t02_iBM"} and snapshot["done"]
        assert snapshot["values"]["limit"] == plant.db.value("limit") and "quality" not in snapshot  # all good
        tag = plant.db["limit"]
        assert snapshot.get("times", {}).get("limit", snapshot["time"]) == round(tag.timestamp, 3)
        # `counter` changes every 10 ms (100/s); the client gets its value at most 10 times a second
        # (on average: a burst of two, then one per period). Counted over 2 s of the values' own
        # time, not of reading: a reader that fell behind on a busy machine reads a backlog at once.
        stamps: list[float] = []
        started = time.monotonic()
        while time.monotonic() - started < 3.0:
            message = json.loads((await ws.receive(timeout=2)).data)
            if message["type"] == "update":
                assert set(message["values"]) <= {"counter", "limit", "=t01_iBM + t02_iBM"}
                if "counter" in message["values"]:
                    stamps.append(message.get("times", {}).get("counter", message["time"]))
        assert stamps, "no update of counter in 3 s"
        counters = sum(stamp < stamps[0] + 2.0 for stamp in stamps)
        assert 10 <= counters <= 2 * 10 + 3, (counters, stamps)


async def test_numbered_subscriptions_say_which_snapshot_is_the_current_sets(plant: Plant) -> None:
    # A page that asks for a second set right after a first (the shell's names, then a view's) may
    # get the first set's snapshot after asking for the second: "subscribed" tells them apart.
    sets = {1: {"counter"}, 2: {"counter", "limit"}, 3: {"limit", "=t01_iBL >= 80"}}
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        for number, items in sets.items():
            await ws.send_json({"type": "subscribe", "items": sorted(items), "id": number})
        answered, snapshots = None, 0
        while not (answered == 3 and snapshots):
            message = await receive_until(ws, lambda message: message["type"] in ("subscribed", "snapshot"))
            if message["type"] == "subscribed":
                assert answered is None or message["id"] > answered, (answered, message)
                answered, snapshots = message["id"], 0
            else:  # one message of up to 500 items: the whole snapshot here
                assert answered is not None and set(message["values"]) == sets[answered] and message["done"], (answered, message)
                snapshots += 1
        for wrong in ("7", True, -1, 2.5, 2**53):
            await ws.send_json({"type": "subscribe", "items": ["counter"], "id": wrong})
            error = await receive_until(ws, "error")
            assert "'id' must be a whole number" in error["message"], (wrong, error)


async def test_expressions_of_views_are_evaluated_on_the_server(plant: Plant) -> None:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_json({"type": "subscribe", "items": ["=t01_iBM + t02_iBM", "=t01_iBL >= 80"]})
        await receive_until(ws, "snapshot")
        plant.drive(t01_iBM=85, t02_iBM=3)
        seen: dict[str, Any] = {}
        deadline = time.monotonic() + 5
        while seen.get("=t01_iBM + t02_iBM") != 88 or seen.get("=t01_iBL >= 80") is not True:
            assert time.monotonic() < deadline, seen
            message = json.loads((await ws.receive(timeout=5)).data)
            seen.update(message.get("values", {}))


async def test_the_quality_of_a_value_travels_with_it(plant: Plant) -> None:
    async with http_client() as session, session.ws_connect(plant.url + "api/live") as ws:
        await ws.send_json({"type": "subscribe", "items": ["r02_xpos", "=t01_iBM + t02_iBM"]})
        await receive_until(ws, "snapshot")
        plant.db.submit_quality(["r02_xpos", "t02_iBM"], Quality.BAD, DRIVER)  # a driver whose robot went away
        message = await receive_until(ws, "update")
        # An expression is as good as the worst tag it reads.
        assert message["quality"] == {"r02_xpos": 2, "=t01_iBM + t02_iBM": 2}
        plant.db.submit_quality(["r02_xpos", "t02_iBM"], Quality.GOOD, DRIVER)
        message = await receive_until(ws, "update")
        assert "quality" not in message and set(message["values"]) == {"r02_xpos", "=t01_iBM + t02_iBM"}


async def test_views_api_serves_the_drawing_as_an_inert_document(plant: Plant) -> None:
    async with http_client() as session:
        async with session.get(plant.url + "api/views") as response:
            assert (await response.json())["views"] == [{"name": "test", "title": "Test view"}]
        async with session.get(plant.url + "api/views/test/svg") as response:
            assert response.headers["Content-Type"].startswith("image/svg+xml")
            assert "sandbox" in response.headers["Content-Security-Policy"]


async def test_login_is_throttled_like_opc_ua_logins(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path)
    try:
        async with http_client() as session:
            for _ in range(5):
                async with session.post(plant.url + "api/login", json={"user": "engineer", "password": "wrong-password"}) as response:
                    assert response.status == 401
            # Even the right password is refused now, without being checked.
            hashed = plant.hmi.sessions.logins.hashed
            async with session.post(plant.url + "api/login", json={"user": "engineer", "password": PASSWORDS["engineer"]}) as response:
                assert response.status == 401
            assert plant.hmi.sessions.logins.hashed == hashed
    finally:
        await plant.stop()


async def test_with_anonymous_off_nothing_is_shown_before_logging_in(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, anonymous="off")
    try:
        async with http_client() as session:
            async with session.get(plant.url + "api/session") as response:
                assert (await response.json())["login_required"] is True
            async with session.get(plant.url + "api/tags") as response:
                assert response.status == 401
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await session.ws_connect(plant.url + "api/live")
            assert refused.value.status == 401
            await http_login(session, plant.url, "viewer")
            async with session.get(plant.url + "api/tags") as response:
                assert response.status == 200
    finally:
        await plant.stop()


async def test_a_silent_live_client_is_dropped_after_its_heartbeats(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, heartbeat=0.3)
    try:
        async with http_client() as session:
            ws = await session.ws_connect(plant.url + "api/live", autoping=False)
            await wait_until(lambda: plant.hmi.hub.dropped == 1, timeout=5, message="the silent client dropped")
            await ws.close()
    finally:
        await plant.stop()


async def test_tls_serves_https_with_a_certificate_made_in_the_state_directory(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, tls=True)
    try:
        assert plant.url.startswith("https://")
        assert (tmp_path / "state" / "hmi" / "tls" / "cert.pem").is_file()
        assert (tmp_path / "state" / "hmi" / "tls" / "key.pem").stat().st_mode & 0o077 == 0
        async with http_client() as session:
            async with session.post(plant.url + "api/login", json={"user": "viewer", "password": PASSWORDS["viewer"]}, ssl=False) as response:
                assert response.status == 200
                cookie = response.headers["Set-Cookie"]
        assert cookie.startswith(f"__Host-softplc_hmi_{plant.hmi.port}=") and "Secure" in cookie
        with pytest.raises(aiohttp.ClientError):
            async with http_client() as session, session.get(plant.url.replace("https://", "http://") + "api/session") as response:
                await response.read()
    finally:
        await plant.stop()
