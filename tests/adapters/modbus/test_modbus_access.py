"""Who may write what over Modbus, and who wrote it: _sys. tags, strings, the peer in the write Origin."""

from __future__ import annotations

import struct

import pytest
from modbus_helpers import mbap, raw_request, start_plant, stop_plant
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.constants import ExcCodes

from softplc.adapters.modbus.address_map import Table
from softplc.core.tagdb import Rule

PLANT = """
version: 1
tags:
  armed:  {type: bool}
  scans:  {type: uint32, access: ro}
  name:   {type: string, initial: "abc", modbus: {words: 4}}
  level:  {type: uint16, initial: 5}
tasks:
  fast:
    interval: 10ms
    programs:
      - {name: bomb, program: "core_programs:Bomb", bind: {armed: armed, scans: scans}}
servers:
  modbus: {}
"""
COMMANDS = {"_sys.reset_stats", "_sys.reset_faults"}


@pytest.fixture
async def plant(tmp_path):
    running = await start_plant(tmp_path, PLANT)
    yield running
    await stop_plant(running)


def exception_code(response) -> int:
    assert response.isError(), f"expected an exception response, got {response}"
    return response.exception_code


def local_address(client: AsyncModbusTcpClient) -> str:
    host, port = client.ctx.transport.get_extra_info("sockname")[:2]
    return f"{host}:{port}"


async def test_every_write_carries_the_peer_of_its_connection(plant):
    events = []
    plant.db.on_write(events.extend)
    other = AsyncModbusTcpClient("127.0.0.1", port=plant.port, timeout=2, retries=0)
    await other.connect()
    try:
        level, name = plant.address("level"), plant.address("name")
        assert not (await plant.client.write_register(level, 7)).isError()
        assert not (await other.write_register(level, 8)).isError()
        assert exception_code(await other.write_registers(name, [0xC328, 0, 0, 0])) == ExcCodes.ILLEGAL_VALUE  # refused by the codec
        assert exception_code(await plant.client.write_registers(name + 2, [0, 0, 5])) == ExcCodes.ILLEGAL_ADDRESS  # half the string
        mine, theirs = local_address(plant.client), local_address(other)
        assert mine != theirs
        seen = [(event.origin.source, event.origin.peer, event.tag, event.accepted) for event in events]
        assert seen == [
            ("modbus", mine, "level", True),
            ("modbus", theirs, "level", True),
            ("modbus", theirs, "name", False),
            ("modbus", mine, "name", False),
        ]
        assert str(events[0].origin) == f"modbus:{mine}"
    finally:
        other.close()


async def test_only_the_command_tags_of_sys_are_in_a_writable_table(plant):
    system = [mapping for mapping in plant.adapter.map.mappings if mapping.name.startswith("_sys.")]
    writable = {mapping.name for mapping in system if mapping.table in (Table.COIL, Table.HOLDING)}
    assert writable == COMMANDS
    assert {mapping.table for mapping in system if mapping.name not in COMMANDS} == {Table.INPUT}


async def test_sys_diagnostic_registers_are_not_writable(plant):
    client, sys_map = plant.client, plant.adapter.map.by_tag
    cycles = sys_map["_sys.fast.cycles"].address
    state = sys_map["_sys.state"]
    await plant.wait_for(lambda: plant.db.value("_sys.fast.cycles") > 0)
    # every write function code at the diagnostics' addresses: 02, nothing applied
    assert exception_code(await client.write_register(cycles, 0)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.write_registers(cycles, [0, 0])) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.write_registers(state.address, [0x4f4b] + [0] * (state.words - 1))) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.readwrite_registers(read_address=cycles, read_count=1, write_address=cycles, values=[0])) \
        == ExcCodes.ILLEGAL_ADDRESS
    mask_write = mbap(9, 1, struct.pack(">BHHH", 22, cycles, 0, 0xFFFF))
    assert (await raw_request(plant.port, mask_write))[7:9] == bytes([0x80 | 22, ExcCodes.ILLEGAL_ADDRESS])
    reset_faults = sys_map["_sys.reset_faults"].address
    # a multi-coil write running from the commands into the unmapped coils after them
    assert exception_code(await client.write_coils(reset_faults, [True, True])) == ExcCodes.ILLEGAL_ADDRESS
    await plant.next_cycles(2)
    assert plant.db.value("_sys.state") == "RUNNING" and plant.db.value("_sys.fast.cycles") > 0
    assert plant.db.value("_sys.reset_faults") is False  # the refused coil write applied nothing


async def test_sys_reset_faults_coil_is_writable_and_clears_a_fault(plant):
    client = plant.client
    bomb = plant.runtime.program("bomb")
    assert not (await client.write_coil(plant.address("armed"), True)).isError()
    await plant.wait_for(lambda: bomb.state.value == "FAULTED")
    assert not (await client.write_coil(plant.address("armed"), False)).isError()
    await plant.next_cycles(2)
    assert bomb.state.value == "FAULTED"  # disarmed, but a fault stays until it is reset
    commands = plant.address("_sys.reset_stats")
    assert not (await client.write_coils(commands, [False, True])).isError()  # both command coils, FC15
    await plant.wait_for(lambda: bomb.state.value == "RUNNING", timeout=3.0)
    await plant.wait_for(lambda: plant.db.value("_sys.reset_faults") is False)  # the runtime clears the command
    assert not (await client.write_coil(plant.address("_sys.reset_faults"), True)).isError()  # FC5 as well


@pytest.mark.parametrize(
    ("name", "registers"),
    [
        ("a lone continuation byte", [0x8000, 0, 0, 0]),
        ("a cut two-byte sequence", [0x61C3, 0, 0, 0]),
        ("an encoded surrogate (CESU-8)", [0xEDA0, 0x8000, 0, 0]),
        ("Latin-1, not UTF-8", [0x6361, 0x66E9, 0, 0]),  # 'caf\xe9'
        ("an overlong encoding of '/'", [0xC0AF, 0, 0, 0]),
    ],
)
async def test_a_string_write_with_invalid_utf8_is_refused_with_03(plant, name, registers):
    events = []
    plant.db.on_write(events.extend)
    address = plant.address("name")
    assert exception_code(await plant.client.write_registers(address, registers)) == ExcCodes.ILLEGAL_VALUE, name
    assert [(event.tag, event.rule) for event in events] == [("name", Rule.TYPE_MISMATCH)]
    await plant.next_cycles(2)
    assert plant.db.value("name") == "abc"
    # the same registers with valid UTF-8 are accepted
    assert not (await plant.client.write_registers(address, [0x6361, 0x66C3, 0xA900, 0])).isError()
    await plant.wait_for(lambda: plant.db.value("name") == "café")
