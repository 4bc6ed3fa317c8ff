"""Modbus links against pymodbus's own server (a SimDevice nobody here wrote) on loopback, on the real clock.

Values in and out, grouped reads (the requests the server sees, counted), quality when the
remote stops answering (UNCERTAIN at 2x the period, BAD at 5x), is killed (BAD at once) and
comes back (GOOD after a reconnect with backoff), exception codes, garbage and values out of
range (BAD with the reason, never a wrong value with good quality), and the remote's answer to
a client's write in the audit (the commands' listeners).
"""

from __future__ import annotations

import asyncio
import struct
from pathlib import Path

import pytest
from pymodbus.constants import ExcCodes

from softplc.core.commands import CommandCall
from softplc.core.plant import AdapterError
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality
from tests.links_support import PymodbusRemote, links_of, start_plant, wait_until

PLANT = """
plant: {{name: linked}}
links:
  press: {{protocol: modbus, host: 127.0.0.1, port: {port}, period: {period}, timeout: 1s, backoff_max: 2s}}
tags:
  count: {{type: int16, link: {{name: press, source: "holding:0"}}}}
  force: {{type: float32, link: {{name: press, source: "holding:1", type: int16, scale: 10}}}}
  level: {{type: float32, max: 100, link: {{name: press, source: "holding:2"}}}}
  total: {{type: uint32, link: {{name: press, source: "holding:4"}}}}
  label: {{type: string, link: {{name: press, source: "holding:6", words: 2}}}}
  pressure: {{type: float64, link: {{name: press, source: "input:0"}}}}
  setpoint: {{type: float32, link: {{name: press, source: "holding:20", direction: out}}}}
  mode: {{type: int16, link: {{name: press, source: "holding:22", direction: both}}}}
  lamp: {{type: bool, link: {{name: press, source: "coil:3", direction: both}}}}
"""


def words(fmt: str, value: object) -> list[int]:
    data = struct.pack(">" + fmt, value)
    return [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]


@pytest.fixture
async def remote():
    server = PymodbusRemote()
    await server.start()
    yield server
    await server.stop()


async def linked(tmp_path: Path, remote: PymodbusRemote, period: str = "50ms"):
    return await start_plant(tmp_path, PLANT.format(port=remote.port, period=period))


async def test_values_come_in_and_go_out_in_grouped_requests(tmp_path: Path, remote: PymodbusRemote) -> None:
    remote.holding[0:8] = [42, 123, *words("f", 12.5), *words("I", 70000), *words("2s", b"ok"), 0]
    remote.inputs[0:4] = words("d", 3.25)
    runtime = await linked(tmp_path, remote)
    db = runtime.db
    try:
        await wait_until(lambda: db.value("count") == 42 and db["count"].quality is Quality.GOOD, what="first poll")
        assert (db.value("force"), db.value("level"), db.value("total"), db.value("label"), db.value("pressure")) == (
            pytest.approx(12.3), 12.5, 70000, "ok", 3.25)
        remote.holding[0] = -7 & 0xFFFF
        await wait_until(lambda: db.value("count") == -7, what="a changed register")
        # Out: the program's (here: a client's) value reaches the remote, scaled and encoded.
        db.submit([("setpoint", 2.5), ("mode", 3)], Origin("test", role=Role.OPERATOR))
        await wait_until(lambda: remote.holding[20] == words("f", 2.5)[0] and remote.holding[22] == 3, what="the writes")
        # Both: the remote's change comes in, and is not echoed back to it.
        writes_before = remote.requests[16] + remote.requests[6]
        remote.holding[22] = 9
        await wait_until(lambda: db.value("mode") == 9, what="the remote's change of a both tag")
        await asyncio.sleep(0.2)
        assert remote.requests[16] + remote.requests[6] == writes_before
        db.submit([("lamp", True)], Origin("test", role=Role.OPERATOR))
        await wait_until(lambda: db.value("lamp") is True and remote.requests[5] + remote.requests[15] >= 1, what="a coil")
        # Grouped: one FC3 for holding 0..7, one FC4 for input 0..3, one FC3 for 22, one FC1 for coil 3 per poll.
        link = links_of(runtime).links["press"]
        assert link.describe()["requests_per_poll"] == 4
        polls_before, reads_before = link.polls, remote.requests[3] + remote.requests[4] + remote.requests[1]
        await asyncio.sleep(0.5)
        polls = link.polls - polls_before
        reads = remote.requests[3] + remote.requests[4] + remote.requests[1] - reads_before
        assert polls >= 4 and reads in range(4 * polls - 4, 4 * polls + 5), (polls, reads)
        assert db.value("_sys.links.press.connected") is True and db.value("_sys.links.press.state") == "up"
    finally:
        await runtime.stop()


async def test_an_exception_code_makes_the_group_bad_with_the_reason_and_an_illegal_address_is_found_alone(
        tmp_path: Path, remote: PymodbusRemote) -> None:
    remote.holding[0] = 5
    runtime = await linked(tmp_path, remote)
    db = runtime.db
    try:
        await wait_until(lambda: db.value("count") == 5 and db["count"].quality is Quality.GOOD)
        remote.exceptions[3] = ExcCodes.DEVICE_FAILURE
        await wait_until(lambda: db["count"].quality is Quality.BAD, what="BAD on exception 04")
        rows = {row["tag"]: row for row in await runtime.commands.call("links.tags", {"link": "press"}, "test")}
        assert rows["count"]["reason"] == "exception 04 (server device failure) reading holding 0..7"
        assert db.value("count") == 5  # the last good value, never a made-up one
        assert db["pressure"].quality is Quality.GOOD  # another request, another verdict
        # An illegal address: the group is read binding by binding, and only the culprit stays BAD.
        remote.exceptions[3] = ExcCodes.ILLEGAL_ADDRESS
        await wait_until(lambda: db["count"].quality is Quality.GOOD, what="the neighbours read one by one")
        assert db["level"].quality is Quality.BAD and db["force"].quality is Quality.GOOD
        rows = {row["tag"]: row for row in await runtime.commands.call("links.tags", {}, "test")}
        assert rows["level"]["reason"] == "exception 02 (illegal data address) reading holding 2..3"
        del remote.exceptions[3]
        await wait_until(lambda: db["level"].quality is Quality.GOOD, what="GOOD once the remote serves it again")
    finally:
        await runtime.stop()


async def test_a_value_out_of_the_tags_range_or_type_is_bad_with_the_reason(tmp_path: Path, remote: PymodbusRemote) -> None:
    remote.holding[2:4] = words("f", 50.0)
    runtime = await linked(tmp_path, remote)
    db = runtime.db
    try:
        await wait_until(lambda: db.value("level") == 50.0 and db["level"].quality is Quality.GOOD)
        remote.holding[2:4] = words("f", 150.0)  # the tag's max is 100
        remote.holding[6:8] = [0xC328, 0]  # not UTF-8
        await wait_until(lambda: db["level"].quality is Quality.BAD and db["label"].quality is Quality.BAD)
        assert db.value("level") == 50.0
        rows = {row["tag"]: row for row in await runtime.commands.call("links.tags", {}, "test")}
        assert "150.0 is above the maximum 100" in rows["level"]["reason"], rows["level"]
        assert "not valid UTF-8" in rows["label"]["reason"], rows["label"]
        remote.holding[2:4] = words("f", 99.0)
        await wait_until(lambda: db.value("level") == 99.0 and db["level"].quality is Quality.GOOD)
    finally:
        await runtime.stop()


async def test_a_silent_remote_makes_tags_uncertain_at_2x_then_bad_at_5x_the_period(tmp_path: Path, remote: PymodbusRemote) -> None:
    runtime = await linked(tmp_path, remote, period="100ms")
    db = runtime.db
    link = links_of(runtime).links["press"]
    try:
        await wait_until(lambda: db["count"].quality is Quality.GOOD)
        await wait_until(lambda: link.last_data is not None and runtime.clock.now() - link.last_data < 0.02)
        remote.hold.clear()  # answers wait: the connection stays open, nothing comes
        silent_from = link.last_data
        assert silent_from is not None
        await wait_until(lambda: db["count"].quality is Quality.UNCERTAIN, timeout=2, what="UNCERTAIN")
        uncertain_at = runtime.clock.now() - silent_from
        assert db.value("_sys.links.press.state") == "late"
        await wait_until(lambda: db["count"].quality is Quality.BAD, timeout=2, what="BAD")
        bad_at = runtime.clock.now() - silent_from
        # The watchdog looks every half period, the journal is applied at the next 10 ms scan, and the
        # machine is shared: the bounds below tell 2x from 5x the period, with room for a loaded loop.
        assert 0.2 <= uncertain_at < 0.2 + 0.2, uncertain_at
        assert 0.5 <= bad_at < 0.5 + 0.2, bad_at
        assert db.value("count") == 0 and db.value("_sys.links.press.connected") is True  # still connected: only late
        remote.hold.set()
        await wait_until(lambda: db["count"].quality is Quality.GOOD, timeout=3, what="GOOD again")
    finally:
        remote.hold.set()
        await runtime.stop()


async def test_a_killed_remote_makes_tags_bad_at_once_and_the_link_reconnects_with_backoff(tmp_path: Path, remote: PymodbusRemote) -> None:
    remote.holding[0] = 11
    runtime = await linked(tmp_path, remote)
    db = runtime.db
    link = links_of(runtime).links["press"]
    try:
        await wait_until(lambda: db.value("count") == 11 and db["count"].quality is Quality.GOOD)
        port = remote.port
        await remote.stop()
        took = await wait_until(lambda: db["count"].quality is Quality.BAD, timeout=2, what="BAD when the remote is gone")
        # The closed connection is noticed at once, not after 5x the period (0.25 s): the link is down, not late
        # (the bound allows for a loaded machine).
        assert took < 0.5, took
        assert db.value("count") == 11 and db.value("_sys.links.press.connected") is False
        assert db.value("_sys.links.press.state") == "down" and db.value("_sys.links.press.error") != ""
        attempts = link.attempts
        await asyncio.sleep(3.0)
        # Backoff from 0.5 s, doubling (max 2 s): about 0.5, 1.5, 3.5 s after the loss — not every period (60 tries).
        assert 1 <= link.attempts - attempts <= 3, link.attempts - attempts
        remote.holding[0] = 12
        await remote.start(port)
        await wait_until(lambda: db.value("count") == 12 and db["count"].quality is Quality.GOOD, timeout=4, what="GOOD after the reconnect")
        assert db.value("_sys.links.press.reconnects") == 1 and db.value("_sys.links.press.connected") is True
    finally:
        await runtime.stop()


async def test_a_remote_answering_garbage_is_dropped_and_its_tags_are_bad_with_the_reason(tmp_path: Path) -> None:
    async def garbage(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while await reader.read(260):
                writer.write(b"\x00\x01HELLO, this is not Modbus\r\n")
                await writer.drain()
        except ConnectionError:
            pass
        finally:
            writer.close()

    server = await asyncio.start_server(garbage, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    runtime = await start_plant(tmp_path, f"""
        links:
          junk: {{protocol: modbus, host: 127.0.0.1, port: {port}, period: 50ms, timeout: 500ms}}
        tags:
          value: {{type: int16, initial: 3, link: {{name: junk, source: "holding:0"}}}}
        """)
    try:
        await wait_until(lambda: "garbage" in runtime.db.value("_sys.links.junk.error"), timeout=5, what="the garbage noticed")
        assert runtime.db["value"].quality is Quality.BAD and runtime.db.value("value") == 3
        assert runtime.db.value("_sys.links.junk.connected") is False
    finally:
        await runtime.stop()
        server.close()


async def test_a_clients_write_goes_out_in_its_name_and_the_remotes_refusal_is_audited(tmp_path: Path, remote: PymodbusRemote) -> None:
    runtime = await linked(tmp_path, remote)
    calls: list[CommandCall] = []
    runtime.commands.on_call(calls.append)
    otto = Origin("hmi", user="otto", peer="127.0.0.1", role=Role.OPERATOR)
    try:
        await wait_until(lambda: runtime.db["count"].quality is Quality.GOOD)
        runtime.db.submit([("setpoint", 4.0)], otto)
        await wait_until(lambda: len(calls) == 1, what="the remote's answer reported")
        assert (calls[0].command, calls[0].origin, calls[0].accepted) == ("links.write", otto, True)
        assert remote.holding[20] == words("f", 4.0)[0]
        remote.exceptions[20] = ExcCodes.ILLEGAL_VALUE
        runtime.db.submit([("setpoint", 5.0)], otto)
        await wait_until(lambda: len(calls) == 2, what="the refusal reported")
        assert calls[1].accepted is False and "exception 03 (illegal data value)" in calls[1].detail, calls[1]
        assert calls[1].arguments == {"tag": "setpoint", "value": 5.0}
        # The command itself, by a viewer: refused by role, like any write.
        with pytest.raises(Exception, match="may not"):
            await runtime.commands.call("links.write", {"tag": "setpoint", "value": 1.0}, Origin("hmi", role=Role.VIEWER))
    finally:
        await runtime.stop()


async def test_a_register_the_remote_does_not_serve_stops_the_start_with_its_location(tmp_path: Path, remote: PymodbusRemote) -> None:
    with pytest.raises(AdapterError) as raised:
        await start_plant(tmp_path, f"""
            links:
              press: {{protocol: modbus, host: 127.0.0.1, port: {remote.port}, period: 50ms}}
            tags:
              fine: {{type: int16, link: {{name: press, source: "holding:10"}}}}
              beyond: {{type: int16, link: {{name: press, source: "holding:11"}}}}
              far: {{type: int16, link: {{name: press, source: "holding:5000"}}}}
            """)
    message = str(raised.value)
    assert "tagdb.yaml:7:50: " in message and "link press: exception 02 (illegal data address) reading holding 5000..5000" in message
    assert "holding:10" not in message and message.count("exception") == 1


async def test_a_late_link_changes_a_both_tags_quality_never_its_local_value(tmp_path: Path, remote: PymodbusRemote) -> None:
    # A program cleared a both tag (the handshake's Ready); the remote has not taken it yet when the
    # link goes late: the tag must say UNCERTAIN with the program's value, not the remote's stale one.
    remote.holding[22] = 5
    runtime = await linked(tmp_path, remote, period="100ms")
    db = runtime.db
    try:
        await wait_until(lambda: db.value("mode") == 5 and db["mode"].quality is Quality.GOOD)
        shown: list[tuple[object, Quality]] = []  # every (value, quality) the tag takes from here on
        undo = db.on_change(lambda tags: shown.extend((tag.value, tag.quality) for tag in tags if tag.name == "mode"))
        remote.hold.clear()  # from now on nothing is answered: neither the polls nor our write
        db.submit([("mode", 6)], "program")
        await wait_until(lambda: db["mode"].quality is Quality.BAD, timeout=3, what="BAD")
        undo()
        # UNCERTAIN at 2x the period, then BAD (a loop held up for 3x the period on a loaded machine
        # goes from GOOD to BAD at once: test_a_silent_remote... checks the steps); the value is the
        # program's throughout.
        assert shown[0] == (6, Quality.GOOD) and shown[-1] == (6, Quality.BAD), shown
        assert {value for value, _ in shown} == {6}, shown
    finally:
        remote.hold.set()
        await runtime.stop()


async def test_a_late_link_sends_a_value_on_its_way_once(tmp_path: Path, remote: PymodbusRemote) -> None:
    # A both tag's write is on its way when the link goes late: the tag's quality changes, its value
    # does not — the same value must not be sent again (a second write, landing after the remote's
    # own change of the tag, would overwrite it).
    remote.holding[22] = 5
    runtime = await linked(tmp_path, remote, period="100ms")
    db = runtime.db
    link = links_of(runtime).links["press"]
    try:
        await wait_until(lambda: db.value("mode") == 5 and db["mode"].quality is Quality.GOOD)
        remote.hold.clear()  # answers wait: the write below, and the polls
        db.submit([("mode", 6)], "program")
        await wait_until(lambda: db["mode"].quality is Quality.UNCERTAIN, timeout=2, what="UNCERTAIN")
        remote.hold.set()  # within the link's 1 s timeout: everything is answered, late
        await wait_until(lambda: remote.holding[22] == 6 and db["mode"].quality is Quality.GOOD, what="the write, and GOOD again")
        await wait_until(lambda: link._flushing is not None and link._flushing.done() and not link._pending, what="the writes done")
        writes = [entry for entry in remote.request_log if entry[0] in (6, 16) and entry[1] <= 22 < entry[1] + entry[2]]
        assert len(writes) == 1, writes
    finally:
        remote.hold.set()
        await runtime.stop()
