"""OPC UA links against asyncua's own Server (default settings, nobody here wrote it) in this process, on loopback.

Values in and out by one subscription (one CreateMonitoredItems request per link, counted at
the server), a remote's bad or uncertain status, a value of another type (garbage) or out of
the tag's range (BAD with the reason, the last good value kept), nodes the remote does not have
or of another type (located errors at start), a write the remote refuses (audited), and 1,000
bound items.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from asyncua import ua

from softplc.core.commands import CommandCall
from softplc.core.plant import AdapterError
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality
from tests.links_support import AsyncuaRemote, links_of, start_plant, wait_until

V = ua.VariantType


@pytest.fixture
async def remote():
    server = AsyncuaRemote()
    await server.start()
    await server.add("Count", 7, V.Int16)
    await server.add("Level", 40.0, V.Double)
    await server.add("Name", "press 1", V.String)
    await server.add("Ready", False, V.Boolean, writable=True)
    await server.add("Setpoint", 0, V.Int32, writable=True)
    await server.add("Small", 0, V.Byte, writable=True)
    yield server
    await server.stop()


def plant(remote: AsyncuaRemote, extra: str = "") -> str:
    return f"""
        plant: {{name: linked}}
        links:
          line2: {{protocol: opcua, endpoint: "{remote.endpoint}", namespace: "{remote.NAMESPACE}", period: 100ms, timeout: 2s}}
        tags:
          count: {{type: int16, link: {{name: line2, source: "ns={{ns}};s=Count"}}}}
          level: {{type: float32, max: 100, link: {{name: line2, source: "ns={{ns}};s=Level"}}}}
          name: {{type: string, link: {{name: line2, source: "ns={{ns}};s=Name"}}}}
          ready: {{type: bool, link: {{name: line2, source: "ns={{ns}};s=Ready", direction: both}}}}
          setpoint: {{type: int32, link: {{name: line2, source: "ns={{ns}};s=Setpoint", direction: out}}}}
          small: {{type: int16, link: {{name: line2, source: "ns={{ns}};s=Small", direction: out}}}}
        {extra}"""


async def test_values_come_in_by_one_subscription_and_go_out(tmp_path: Path, remote: AsyncuaRemote) -> None:
    runtime = await start_plant(tmp_path, plant(remote))
    db = runtime.db
    try:
        await wait_until(lambda: db.value("count") == 7 and db["count"].quality is Quality.GOOD, what="the first values")
        assert (db.value("level"), db.value("name"), db.value("ready")) == (40.0, "press 1", False)
        # One request per connection: count, level, name and the both-tag ready (a loaded machine
        # may have had the link reconnect: each connection asks once, with every item).
        assert remote.created == [3 + 1] * (1 + db.value("_sys.links.line2.reconnects")), remote.created
        await remote.set("Count", -3, V.Int16)
        await wait_until(lambda: db.value("count") == -3, what="a change")
        db.submit([("setpoint", 123456), ("ready", True)], Origin("test", role=Role.OPERATOR))
        await wait_until(lambda: db.value("ready") is True, what="local apply")
        await wait_until(lambda: remote.nodes["Setpoint"] is not None and _read(remote, "Setpoint") == 123456, what="setpoint out")
        await wait_until(lambda: _read(remote, "Ready") is True, what="ready out")
        await remote.set("Ready", False, V.Boolean)  # the remote clears it: it comes back in
        await wait_until(lambda: db.value("ready") is False, what="the remote's change of a both tag")
        link = links_of(runtime).links["line2"]
        assert link.writes["refused"] == 0 and db.value("_sys.links.line2.state") == "up"
    finally:
        await runtime.stop()


async def test_a_write_request_that_fails_while_the_link_stays_up_is_sent_again(tmp_path: Path, remote: AsyncuaRemote) -> None:
    # A remote that fails a Write request as a whole (a service fault; or an answer later than the
    # timeout) while the connection stays up: no reconnect follows, so the link itself must send
    # the value again (it stayed pending until the next local change: the remote never got it).
    from asyncua.common.callback import CallbackType

    faults = []

    async def fail_once(event: object, dispatcher: object) -> None:
        if not faults:
            faults.append(event)
            raise RuntimeError("a remote failing one Write request")  # asyncua answers BadInternalError

    runtime = await start_plant(tmp_path, plant(remote))
    db = runtime.db
    try:
        await wait_until(lambda: db["count"].quality is Quality.GOOD, what="the link up")
        link = links_of(runtime).links["line2"]
        remote.server.subscribe_server_callback(CallbackType.PreWrite, fail_once)
        reconnects = db.value("_sys.links.line2.reconnects")
        db.submit([("setpoint", 4242)], Origin("test", role=Role.OPERATOR))
        await wait_until(lambda: link.writes["failed"] == 1, what="the failed write")
        await wait_until(lambda: _read(remote, "Setpoint") == 4242, timeout=10, what="the value sent again")
        assert len(faults) == 1 and db.value("_sys.links.line2.reconnects") == reconnects
        assert db.value("setpoint") == 4242 and link.writes["ok"] >= 1
    finally:
        await runtime.stop()


_values: dict[str, object] = {}


def _read(remote: AsyncuaRemote, name: str) -> object:
    """The server's value, read synchronously from its address space (the server runs in this loop)."""
    return remote.server.iserver.aspace.read_attribute_value(remote.nodes[name].nodeid, ua.AttributeIds.Value).Value.Value


async def test_a_bad_or_uncertain_status_another_type_or_a_value_out_of_range_is_never_good(tmp_path: Path, remote: AsyncuaRemote) -> None:
    runtime = await start_plant(tmp_path, plant(remote))
    db = runtime.db

    async def reasons() -> dict[str, str]:
        return {row["tag"]: row["reason"] for row in await runtime.commands.call("links.tags", {}, "test")}

    try:
        await wait_until(lambda: db.value("count") == 7 and db.value("name") == "press 1" and db["level"].quality is Quality.GOOD)
        await remote.set("Count", 9, V.Int16, ua.StatusCodes.BadSensorFailure)
        await remote.set("Level", 150.0, V.Double)  # the tag's max is 100
        await remote.retype("Name", 42, V.Int32)  # a number where the node was a string
        await wait_until(lambda: all(db[n].quality is Quality.BAD for n in ("count", "level", "name")), what="BAD")
        assert (db.value("count"), db.value("level"), db.value("name")) == (7, 40.0, "press 1")  # last good values
        found = await reasons()
        assert found["count"] == "the remote says BadSensorFailure"
        assert "150.0 is above the maximum 100" in found["level"]
        assert found["name"] == "the remote sent Int32 42 for a string tag"
        await remote.set("Count", 8, V.Int16, ua.StatusCodes.UncertainLastUsableValue)
        await wait_until(lambda: db.value("count") == 8 and db["count"].quality is Quality.UNCERTAIN, what="UNCERTAIN")
        await remote.retype("Count", 70000, V.Int32)
        await wait_until(lambda: db["count"].quality is Quality.BAD, what="an Int32 that does not fit int16")
        assert "does not fit in int16" in (await reasons())["count"]
        await remote.retype("Count", 10, V.Int16)
        await remote.set("Level", 99.5, V.Double)
        await wait_until(lambda: db.value("count") == 10 and db["count"].quality is Quality.GOOD and db["level"].quality is Quality.GOOD)
        assert db.value("_sys.links.line2.bad_tags") == 1  # name
    finally:
        await runtime.stop()


async def test_a_write_the_remote_refuses_is_audited_with_its_reason(tmp_path: Path, remote: AsyncuaRemote) -> None:
    runtime = await start_plant(tmp_path, plant(remote))
    calls: list[CommandCall] = []
    runtime.commands.on_call(calls.append)
    otto = Origin("opcua", user="otto", peer="10.0.0.7:50000", role=Role.OPERATOR)
    try:
        await wait_until(lambda: runtime.db.value("count") == 7 and runtime.db["count"].quality is Quality.GOOD)
        runtime.db.submit([("small", 300)], otto)  # the remote node is a Byte
        await wait_until(lambda: len(calls) == 1)
        assert calls[0].accepted is False and "300 does not fit the remote node's Byte (0..255)" in calls[0].detail
        await remote.nodes["Setpoint"].set_read_only()  # the remote's own refusal
        runtime.db.submit([("setpoint", 5)], otto)
        await wait_until(lambda: len(calls) == 2)
        assert (calls[1].command, calls[1].origin, calls[1].accepted) == ("links.write", otto, False)
        assert "refused setpoint = 5: Bad" in calls[1].detail, calls[1].detail
        runtime.db.submit([("small", 200)], otto)
        await wait_until(lambda: len(calls) == 3)
        assert calls[2].accepted and _read(remote, "Small") == 200
    finally:
        await runtime.stop()


async def test_nodes_the_remote_does_not_have_or_of_another_type_stop_the_start_with_their_location(tmp_path: Path, remote: AsyncuaRemote) -> None:
    await remote.add("Total", 1.5, V.Double)
    await remote.add("Locked", 1, V.Int16)  # read-only for clients
    with pytest.raises(AdapterError) as raised:
        await start_plant(tmp_path, plant(remote, """
          missing: {type: int16, link: {name: line2, source: "ns={ns};s=Nothing"}}
          wrong: {type: int16, link: {name: line2, source: "ns={ns};s=Total"}}
          locked: {type: int16, link: {name: line2, source: "ns={ns};s=Locked", direction: out}}
        """))
    lines = str(raised.value).splitlines()[1:]
    assert len(lines) == 3, lines
    assert lines[0].endswith("link line2: node ns={ns};s=Nothing of the remote: BadNodeIdUnknown") and "tagdb.yaml:13:54: " in lines[0]
    assert "node ns={ns};s=Total: the remote node is Double, the tag is int16 (which needs an integer type)" in lines[1]
    assert "node ns={ns};s=Locked is not writable for an anonymous session (direction out)" in lines[2]


async def test_a_thousand_items_are_subscribed_in_one_request(tmp_path: Path) -> None:
    remote = AsyncuaRemote()
    await remote.start()
    try:
        for index in range(1000):
            await remote.add(f"V{index}", index, V.Int32)
        tags = "\n".join(f"  v{i}: {{type: int32, link: {{name: big, source: \"ns={{ns}};s=V{i}\"}}}}" for i in range(1000))
        started = time.monotonic()
        runtime = await start_plant(tmp_path, f"""
links:
  big: {{protocol: opcua, endpoint: "{remote.endpoint}", namespace: "{remote.NAMESPACE}", period: 100ms}}
tags:
{tags}
""")
        try:
            await wait_until(lambda: all(runtime.db[f"v{i}"].quality is Quality.GOOD for i in range(0, 1000, 50))
                             and runtime.db.value("v999") == 999, timeout=20, what="1,000 items GOOD")
            assert remote.created == [1000]
            assert runtime.db.value("_sys.links.big.bad_tags") == 0
            print(f"1,000 items: all good {time.monotonic() - started:.2f} s after the start began")
        finally:
            await runtime.stop()
    finally:
        await remote.stop()
