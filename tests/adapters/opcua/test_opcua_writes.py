"""Writes over OPC UA that must be refused cleanly: strings that are not valid UTF-8 (beside Modbus
and a retained tag), the runtime's diagnostic `_sys.` tags; and who wrote, for the audit trail."""

from __future__ import annotations

import logging
import textwrap
from contextlib import asynccontextmanager
from pathlib import Path

from asyncua import ua
from pymodbus.client import AsyncModbusTcpClient

from softplc.adapters.modbus.server import ModbusAdapter
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.adapters.opcua import OpcUaServer, OpcUaSettings
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.tagdb import WriteEvent
from tests.opcua_support import add_users, client_for, running_plant, wait_until

STRINGS = """
version: 1
tags:
  label:   {type: string, retain: true, initial: first}
  count:   {type: int32}
tasks:
  fast:
    interval: 10ms
    programs: []
"""
INVALID = "ab\udcffcd"  # asyncua sends it as the bytes 61 62 ff 63 64: not UTF-8


@asynccontextmanager
async def _plant(directory: Path):
    """OPC UA and Modbus over one runtime whose state (retained values) lives in `directory`."""
    path = directory / "tagdb.yaml"
    path.write_text(textwrap.dedent(STRINGS))
    config = load_config(path)
    state = directory / "state"
    if not state.exists():
        state.mkdir()
        add_users(state)
    modbus = ModbusAdapter(config, ModbusSettings(enabled=True, host="127.0.0.1", port=0, unit_id=1))
    opcua = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/", security=("None",)))
    runtime = Runtime(config, RealClock(), state_dir=state)
    runtime.add_adapter(modbus)
    runtime.add_adapter(opcua)
    await runtime.start()
    try:
        yield runtime, modbus, opcua
    finally:
        await runtime.stop()


async def _modbus_reads_label(modbus: ModbusAdapter) -> None:
    mapping = modbus.map.by_tag["label"]
    client = AsyncModbusTcpClient("127.0.0.1", port=modbus.port, timeout=2, retries=0)
    await client.connect()
    try:
        response = await client.read_holding_registers(mapping.address, count=mapping.words)
        assert not response.isError(), response
    finally:
        client.close()


async def test_a_string_that_is_not_utf8_is_refused_per_item_and_stored_nowhere(tmp_path, caplog) -> None:
    caplog.set_level(logging.INFO)
    async with _plant(tmp_path) as (runtime, modbus, opcua):
        async with client_for(opcua, "operator") as client:
            ns = opcua.namespace_index
            label, count = client.get_node(ua.NodeId("label", ns)), client.get_node(ua.NodeId("count", ns))
            # In one Write: the bad string, a good item, the bad bytes in a NodeId, and to a number tag.
            results = await client.write_values(
                [label, count, client.get_node(ua.NodeId("lab\udcffel", ns)), count],
                [ua.Variant(INVALID, ua.VariantType.String), ua.Variant(7, ua.VariantType.Int32),
                 ua.Variant("x", ua.VariantType.String), ua.Variant(INVALID, ua.VariantType.String)],
                raise_on_partial_error=False)
            assert [r.value for r in results] == [
                ua.StatusCodes.BadTypeMismatch, ua.StatusCodes.Good, ua.StatusCodes.BadNodeIdUnknown, ua.StatusCodes.BadTypeMismatch]
            await wait_until(lambda: runtime.db.value("count") == 7)  # the good item of the same Write was applied
            assert runtime.db.value("label") == "first" and await label.read_value() == "first"
            await _modbus_reads_label(modbus)
            # A valid non-ASCII string is fine, and is what gets retained.
            assert (await client.write_values([label], [ua.Variant("grün", ua.VariantType.String)]))[0].is_good()
            await wait_until(lambda: runtime.db.value("label") == "grün")
            assert (await client.write_values([label], [ua.Variant(INVALID, ua.VariantType.String)], raise_on_partial_error=False))[0].value \
                == ua.StatusCodes.BadTypeMismatch
            await _modbus_reads_label(modbus)
    assert not [record for record in caplog.records if record.exc_info or record.levelno >= logging.ERROR]
    # Every log line can be written to a UTF-8 file (the bad bytes are shown as \xff, not as lone surrogates).
    for record in caplog.records:
        record.getMessage().encode("utf-8")
    async with _plant(tmp_path) as (runtime, modbus, opcua):
        assert runtime.db.value("label") == "grün"  # the retained value is the last valid one
        await _modbus_reads_label(modbus)


async def test_nobody_writes_the_diagnostic_tags_but_the_commands_still_work(tmp_path) -> None:
    async with running_plant(tmp_path, security=("None",)) as (runtime, server):
        db = runtime.db
        await wait_until(lambda: db.value("_sys.state") == "RUNNING")
        diagnostics = {"_sys.state": ua.Variant("STOPPED", ua.VariantType.String),
                       "_sys.error": ua.Variant("spoofed", ua.VariantType.String),
                       "_sys.fast.cycles": ua.Variant(1, ua.VariantType.UInt32)}
        async with client_for(server, "engineer") as engineer:
            before = {name: db.value(name) for name in diagnostics}
            nodes = [engineer.get_node(server.node_id(name)) for name in diagnostics]
            results = await engineer.write_values(nodes, list(diagnostics.values()), raise_on_partial_error=False)
            assert [r.value for r in results] == [ua.StatusCodes.BadNotWritable] * 3
            cycles = runtime.tasks[0].stats.cycles
            await wait_until(lambda: runtime.tasks[0].stats.cycles > cycles + 3)
            assert db.value("_sys.state") == before["_sys.state"] == "RUNNING" and db.value("_sys.error") == before["_sys.error"]
            assert db.value("_sys.fast.cycles") > 1
            level = (await engineer.get_node(server.node_id("_sys.state")).read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value
            assert level == 1
        # The command tags accept writes from an operator and an engineer, and the runtime executes them.
        executed: list[bool] = []
        stop = db.on_change(lambda tags: executed.extend(t.value for t in tags if t.name == "_sys.reset_faults"))
        try:
            for user in ("operator", "engineer"):
                async with client_for(server, user) as client:
                    node = client.get_node(server.node_id("_sys.reset_faults"))
                    assert (await node.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value == 3
                    done = len(executed)
                    results = await client.write_values([node], [ua.Variant(True, ua.VariantType.Boolean)])
                    assert results[0].is_good()
                    await wait_until(lambda done=done: executed[done:] == [True, False])  # set, then cleared once done
        finally:
            stop()


async def test_an_opc_ua_write_carries_the_client_address_for_the_audit_trail(tmp_path) -> None:
    async with running_plant(tmp_path, security=("None",)) as (runtime, server):
        events: list[WriteEvent] = []
        stop = runtime.db.on_write(events.extend)
        try:
            async with client_for(server, "operator") as client:
                nodes = [client.get_node(server.node_id(tag)) for tag in ("i32", "ro_i32")]
                await client.write_values(nodes, [ua.Variant(5, ua.VariantType.Int32)] * 2, raise_on_partial_error=False)
        finally:
            stop()
        assert [(event.tag, event.accepted) for event in events] == [("ro_i32", False), ("i32", True)]
        for event in events:
            assert (event.origin.source, event.origin.user, event.origin.peer, event.origin.role.value) == \
                ("opcua", "operator", "127.0.0.1", "operator")
