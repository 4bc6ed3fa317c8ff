"""Modbus TCP and OPC UA serve one tag database: writes and scan outputs cross between them."""

from __future__ import annotations

import asyncio
import logging
import textwrap
import time
from pathlib import Path

import pytest
import pytest_asyncio
from asyncua import Client, ua
from modbus_helpers import value_of, words_of
from pymodbus.client import AsyncModbusTcpClient

from softplc.adapters.modbus.server import ModbusAdapter
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.adapters.opcua import OpcUaServer, OpcUaSettings, Role, UserStore
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.tagdb import Origin

PLANT = """
version: 1
tags:
  setpoint: {type: float64, min: -1000, max: 1000}
  doubled:  {type: float64, access: ro}
  scans:    {type: uint32, access: ro}
  request:  {type: int32}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: doubler
        program: modbus_helpers:Doubler
        bind: {setpoint: setpoint, doubled: doubled, scans: scans}
servers:
  modbus: {unit_id: 1}
"""
OPERATOR = ("op", "operator-pass-1")

# One plant for the module: starting an OPC UA server takes ~2 s.
pytestmark = pytest.mark.asyncio(loop_scope="module")


class Changes:
    """asyncua subscription handler collecting (tag, value, source timestamp) as they arrive."""

    def __init__(self) -> None:
        self.queue: asyncio.Queue[tuple[str, object, float]] = asyncio.Queue()

    def datachange_notification(self, node, value, data) -> None:
        stamp = data.monitored_item.Value.SourceTimestamp
        self.queue.put_nowait((node.nodeid.Identifier, value, stamp.timestamp() if stamp else 0.0))

    async def wait_for(self, tag: str, value: object = None, timeout: float = 5.0) -> float:
        """The source timestamp of the first notification of `tag` == `value` (any value if None)."""
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"no notification {tag} = {value!r} within {timeout} s")
            name, got, stamp = await asyncio.wait_for(self.queue.get(), remaining)
            if name == tag and (value is None or got == value):
                return stamp


async def next_cycles(runtime: Runtime, count: int = 2) -> None:
    """Wait until `count` more cycles of the task have run (so the write journal was applied)."""
    task = runtime.tasks[0]
    target, deadline = task.stats.cycles + count, time.monotonic() + 5
    while task.stats.cycles < target:
        assert time.monotonic() < deadline, "the scan stopped"
        await asyncio.sleep(0.005)


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    tmp_path: Path = tmp_path_factory.mktemp("cross")
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(PLANT))
    config = load_config(path)
    state = tmp_path / "state"
    state.mkdir()
    UserStore(state / "users.yaml").add(OPERATOR[0], Role.OPERATOR, OPERATOR[1])
    modbus = ModbusAdapter(config, ModbusSettings(enabled=True, host="127.0.0.1", port=0, unit_id=1))
    opcua = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/"))
    runtime = Runtime(config, RealClock(), state_dir=state)
    runtime.add_adapter(modbus)
    runtime.add_adapter(opcua)
    await runtime.start()
    modbus_client = AsyncModbusTcpClient("127.0.0.1", port=modbus.port, timeout=2, retries=0)
    await modbus_client.connect()
    opcua_client = Client(opcua.endpoint, timeout=4)
    opcua_client.set_user(OPERATOR[0])
    opcua_client.set_password(OPERATOR[1])
    await opcua_client.connect()
    try:
        yield runtime, modbus, opcua, modbus_client, opcua_client
    finally:
        await opcua_client.disconnect()
        modbus_client.close()
        await runtime.stop()


async def test_a_modbus_write_reaches_an_opc_ua_subscriber_after_the_next_scan(plant):
    runtime, modbus, opcua, mb, ua_client = plant
    changes = Changes()
    subscription = await ua_client.create_subscription(5, changes)
    nodes = [ua_client.get_node(opcua.node_id(name)) for name in ("setpoint", "doubled")]
    await subscription.subscribe_data_change(nodes)
    await changes.wait_for("setpoint")  # the current values arrive first
    await changes.wait_for("doubled")
    cycles = runtime.tasks[0].stats.cycles
    written = time.time()
    response = await mb.write_registers(modbus.map.by_tag["setpoint"].address, words_of("d", 21.5))
    assert not response.isError()
    # journaled, not applied mid-scan: the tag changes only at a cycle boundary after the write
    assert runtime.db.value("setpoint") == 0.0 or runtime.tasks[0].stats.cycles > cycles
    stamp = await changes.wait_for("setpoint", 21.5)
    assert stamp >= written - 0.05  # changed after the write (timestamps are the runtime's wall clock)
    # and the program saw it in the next scan: its output reaches the subscriber too
    await changes.wait_for("doubled", 43.0)
    await subscription.delete()


async def test_a_program_output_is_readable_over_both_protocols(plant):
    runtime, modbus, opcua, mb, ua_client = plant
    await mb.write_registers(modbus.map.by_tag["setpoint"].address, words_of("d", -7.25))
    deadline = time.monotonic() + 5
    while runtime.db.value("doubled") != -14.5:
        assert time.monotonic() < deadline, "the scan never produced doubled = -14.5"
        await asyncio.sleep(0.005)
    # The address space follows the tag database through the OPC UA publisher, a push behind the
    # scan (a Read right after the change may still see the old value): wait for it, 5 s at most.
    node = ua_client.get_node(opcua.node_id("doubled"))
    while (over_opcua := await node.read_value()) != -14.5:
        assert time.monotonic() < deadline, f"OPC UA reads doubled = {over_opcua}, the tag database -14.5"
        await asyncio.sleep(0.005)
    registers = (await mb.read_input_registers(modbus.map.by_tag["doubled"].address, count=4)).registers
    assert over_opcua == value_of("d", registers) == -14.5
    # a value the scan rewrites every cycle: both protocols follow it
    scans = modbus.map.by_tag["scans"].address
    first = value_of("I", (await mb.read_input_registers(scans, count=2)).registers)
    await next_cycles(runtime, 3)
    over_opcua = await ua_client.get_node(opcua.node_id("scans")).read_value()
    over_modbus = value_of("I", (await mb.read_input_registers(scans, count=2)).registers)
    assert first < over_opcua <= over_modbus


async def test_an_opc_ua_write_is_read_over_modbus_and_rules_agree(plant):
    runtime, modbus, opcua, mb, ua_client = plant
    request = ua_client.get_node(opcua.node_id("request"))
    await request.write_value(ua.DataValue(ua.Variant(-123456, ua.VariantType.Int32)))
    address = modbus.map.by_tag["request"].address
    deadline = time.monotonic() + 5
    while value_of("i", (await mb.read_holding_registers(address, count=2)).registers) != -123456:
        assert time.monotonic() < deadline, "the OPC UA write never showed up over Modbus"
        await asyncio.sleep(0.005)
    # the same out-of-range value is refused by both servers, for the same reason
    setpoint = ua_client.get_node(opcua.node_id("setpoint"))
    with pytest.raises(ua.UaStatusCodeError) as refused:
        await setpoint.write_value(ua.DataValue(ua.Variant(5000.0, ua.VariantType.Double)))
    assert refused.value.code == ua.StatusCodes.BadOutOfRange
    response = await mb.write_registers(modbus.map.by_tag["setpoint"].address, words_of("d", 5000.0))
    assert response.isError() and response.exception_code == 3
    await next_cycles(runtime)
    assert runtime.db.value("setpoint") != 5000.0


async def test_a_forced_tag_refuses_writes_over_both_protocols_with_their_own_code_and_no_traceback(plant, caplog):
    runtime, modbus, opcua, mb, ua_client = plant
    engineer = Origin("test", "engineer", role=Role.ENGINEER)
    await runtime.commands.call("tags.force", {"tag": "request", "value": 7}, engineer)
    await next_cycles(runtime)
    assert runtime.db["request"].forced
    caplog.clear()
    try:
        for _ in range(3):  # each refusal alike: no KeyError, no server failure (04), no traceback
            response = await mb.write_registers(modbus.map.by_tag["request"].address, words_of("i", 99))
            assert response.isError() and response.exception_code == 2  # docs/modbus.md: forced → 02
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await ua_client.get_node(opcua.node_id("request")).write_value(ua.DataValue(ua.Variant(99, ua.VariantType.Int32)))
        assert refused.value.code == ua.StatusCodes.BadLocked
        await next_cycles(runtime)
        assert runtime.db.value("request") == 7
    finally:
        await runtime.commands.call("tags.unforce", {"tag": "request"}, engineer)
    assert not [record for record in caplog.records if record.exc_info or record.levelno >= logging.ERROR]
