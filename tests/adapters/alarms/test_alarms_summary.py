"""Summary tags for Modbus and legacy SCADA: counts, the most urgent priority, and acknowledge-all."""

from __future__ import annotations

import asyncio
import time

from pymodbus.client import AsyncModbusTcpClient

from softplc.adapters.modbus.server import ModbusAdapter
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.tagdb import Rule
from tests.alarms_support import DRIVER, PEOPLE, call, client_write, plant, simulate, write

ALARMS = """
definitions:
  - {name: level_hi, limit: {tag: level, hi: 90}, priority: high}
  - {name: nav_failed, discrete: {tag: navstate, value: failed}, priority: low}
  - {name: flag_on, condition: flag, priority: critical}
"""


async def test_counts_follow_the_alarms(tmp_path) -> None:
    steps = [write(1.05, "level", 95), write(1.05, "navstate", "failed"), write(2.05, "flag", True),
             call(3.05, "alarms.shelve", alarm="flag_on", reason="test", duration=60), write(4.05, "level", 10)]
    run = await simulate(tmp_path, plant(ALARMS), steps, 8)
    db = run.runtime.db
    assert db.value("_sys.alarms.active") == 1  # nav_failed only: level_hi returned, flag_on shelved
    assert db.value("_sys.alarms.unacknowledged") == 2  # nav_failed active and level_hi returned
    assert db.value("_sys.alarms.highest_priority") == 1 and db.value("_sys.alarms.shelved") == 1


async def test_acknowledge_all_tag_refuses_a_viewer_and_acknowledges_as_an_operator(tmp_path) -> None:
    steps = [write(1.05, "level", 95), write(1.05, "navstate", "failed"),
             client_write(2.05, "_sys.alarms.acknowledge_all", True, "viewer"),
             client_write(3.05, "_sys.alarms.acknowledge_all", True, "operator")]
    run = await simulate(tmp_path, plant(ALARMS), steps, 5)
    viewer, operator = [result for _, command, result in run.results if command == "write _sys.alarms.acknowledge_all"]
    assert viewer is not None and viewer.rule is Rule.ACCESS_DENIED and operator is None
    assert [entry for entry in run.transitions() if entry[1] == "acknowledged"] == [
        (3.1, "acknowledged", "acknowledged"), (3.1, "acknowledged", "acknowledged")]
    assert {event.data["user"] for event in run.events if event.data["transition"] == "acknowledged"} == {"operator"}
    assert run.runtime.db.value("_sys.alarms.unacknowledged") == 0
    assert run.runtime.db.value("_sys.alarms.acknowledge_all") is False


async def test_modbus_reads_the_counts_and_acknowledges_all_with_a_coil(tmp_path) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(plant(ALARMS))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    modbus = ModbusAdapter(config, ModbusSettings(enabled=True, port=0))
    for adapter in build_adapters(config, None):
        if adapter.name == "alarms":
            runtime.add_adapter(adapter)
    runtime.add_adapter(modbus)
    await runtime.start()
    client = AsyncModbusTcpClient("127.0.0.1", port=modbus.port, timeout=2, retries=0)
    await client.connect()
    mapping = modbus.map.by_tag

    async def read(tag: str) -> int:
        entry = mapping[tag]
        reply = await client.read_input_registers(entry.address, count=entry.words, device_id=1)
        assert not reply.isError(), reply
        value = 0
        for word in reply.registers:
            value = value << 16 | word
        return value

    async def wait(condition, timeout: float = 3.0) -> None:
        deadline = time.monotonic() + timeout
        while not await condition():
            assert time.monotonic() < deadline, "not within the timeout"
            await asyncio.sleep(0.01)

    try:
        runtime.db.submit([("level", 95.0), ("navstate", "failed")], DRIVER)

        async def both_waiting() -> bool:
            return await read("_sys.alarms.unacknowledged") == 2

        await wait(both_waiting)
        assert await read("_sys.alarms.active") == 2 and await read("_sys.alarms.highest_priority") == 3
        coil = mapping["_sys.alarms.acknowledge_all"]
        reply = await client.write_coil(coil.address, True, device_id=1)
        assert not reply.isError(), reply

        async def none_waiting() -> bool:
            return await read("_sys.alarms.unacknowledged") == 0

        await wait(none_waiting)
        assert await read("_sys.alarms.active") == 2
        coils = await client.read_coils(coil.address, count=1, device_id=1)
        assert coils.bits[0] is False  # a command tag: back to false once carried out
        rows = await runtime.commands.call("alarms.journal", {"transition": "acknowledged"}, PEOPLE["viewer"])
        assert sorted(row["alarm"] for row in rows) == ["level_hi", "nav_failed"]
        assert {(row["origin"].split(":")[0], row["role"], row["comment"]) for row in rows} == {("modbus", "operator", "acknowledge-all tag")}
        assert all(row["origin"].startswith("modbus:127.0.0.1:") for row in rows)  # the peer that wrote the tag
    finally:
        client.close()
        await runtime.stop()
