"""Modbus TCP server against a real pymodbus client on loopback: every table and encoding."""

from __future__ import annotations

import pytest
from modbus_helpers import ModbusPlant, start_plant, stop_plant, value_of, words_of

PLANT = """
version: 1
tags:
  b_rw:      {type: bool}
  b_ro:      {type: bool, access: ro, initial: true}
  i16:       {type: int16, min: -1000, max: 1000, initial: -5}
  u16:       {type: uint16, initial: 65000}
  i32:       {type: int32, initial: -70000}
  u32:       {type: uint32, initial: 4000000000}
  f32:       {type: float32, initial: 1.5}
  f64:       {type: float64, initial: 2.25, min: -1000000, max: 1000000}
  f32_le:    {type: float32, initial: -0.75, modbus: {word_order: little}}
  f64_le:    {type: float64, initial: 0.001, modbus: {word_order: little}}
  level:     {type: float32, min: 0, max: 100, initial: 12.34, modbus: {scale: 100}}
  tenths:    {type: uint16, initial: 25, modbus: {scale: 10}}
  big_x:     {type: float64, initial: 123456.7, modbus: {scale: 10, register_type: int32}}
  ro_num:    {type: float32, access: ro, initial: 3.5}
  label:     {type: string, initial: "héllo", modbus: {words: 4}}
  ro_label:  {type: string, access: ro, initial: "a long read-only text", modbus: {words: 3}}
  hidden:    {type: int16, modbus: {enabled: false}}
  setpoint:  {type: float64}
  doubled:   {type: float64, access: ro}
  scans:     {type: uint32, access: ro}
  pinned:    {type: int16, initial: 77, modbus: {address: 500}}
  flag_reg:  {type: bool, initial: true, modbus: {table: holding, address: 502}}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: doubler
        program: modbus_helpers:Doubler
        bind: {setpoint: setpoint, doubled: doubled, scans: scans}
servers:
  modbus: {unit_id: 3}
"""

UNIT = 3


@pytest.fixture
async def plant(tmp_path):
    running = await start_plant(tmp_path, PLANT)
    yield running
    await stop_plant(running)


async def read_holding(plant: ModbusPlant, tag: str, count: int) -> list[int]:
    response = await plant.client.read_holding_registers(plant.address(tag), count=count, device_id=UNIT)
    assert not response.isError(), response
    return response.registers


async def read_input(plant: ModbusPlant, tag: str, count: int) -> list[int]:
    response = await plant.client.read_input_registers(plant.address(tag), count=count, device_id=UNIT)
    assert not response.isError(), response
    return response.registers


async def write_holding(plant: ModbusPlant, tag: str, words: list[int]) -> None:
    response = await plant.client.write_registers(plant.address(tag), words, device_id=UNIT)
    assert not response.isError(), response


async def test_every_table_serves_the_initial_values(plant):
    client, address = plant.client, plant.address
    coils = await client.read_coils(address("b_rw"), count=1, device_id=UNIT)
    assert coils.bits[0] is False
    inputs = await client.read_discrete_inputs(address("b_ro"), count=1, device_id=UNIT)
    assert inputs.bits[0] is True
    assert value_of("h", await read_holding(plant, "i16", 1)) == -5
    assert value_of("H", await read_holding(plant, "u16", 1)) == 65000
    assert value_of("i", await read_holding(plant, "i32", 2)) == -70000
    assert value_of("I", await read_holding(plant, "u32", 2)) == 4000000000
    assert value_of("f", await read_holding(plant, "f32", 2)) == 1.5
    assert value_of("d", await read_holding(plant, "f64", 4)) == 2.25
    assert value_of("f", await read_holding(plant, "f32_le", 2), "little") == -0.75
    assert value_of("d", await read_holding(plant, "f64_le", 4), "little") == 0.001
    assert value_of("f", await read_input(plant, "ro_num", 2)) == 3.5
    assert value_of("h", await read_holding(plant, "pinned", 1)) == 77
    assert await read_holding(plant, "flag_reg", 1) == [1]
    assert "hidden" not in plant.adapter.map.by_tag


async def test_scaled_values_are_integers_on_the_wire(plant):
    assert value_of("h", await read_holding(plant, "level", 1)) == 1234
    assert value_of("H", await read_holding(plant, "tenths", 1)) == 250
    assert value_of("i", await read_holding(plant, "big_x", 2)) == 1234567
    await write_holding(plant, "level", [5678])
    await write_holding(plant, "tenths", [120])
    await write_holding(plant, "big_x", words_of("i", -25))
    await plant.wait_for(lambda: plant.db.value("big_x") == -2.5)
    assert plant.db.value("level") == pytest.approx(56.78, abs=1e-5)
    assert plant.db.value("tenths") == 12
    assert value_of("h", await read_holding(plant, "level", 1)) == 5678


async def test_strings_in_registers(plant):
    words = await read_holding(plant, "label", 4)
    data = b"".join(w.to_bytes(2, "big") for w in words)
    assert data == "héllo".encode() + b"\0\0"
    ro_words = await read_input(plant, "ro_label", 3)
    assert b"".join(w.to_bytes(2, "big") for w in ro_words) == b"a long"  # truncated to 3 registers
    await write_holding(plant, "label", [int.from_bytes(b"OK", "big"), 0, 0, 0])
    await plant.wait_for(lambda: plant.db.value("label") == "OK")


@pytest.mark.parametrize(
    ("tag", "fmt", "value", "order"),
    [
        ("i16", "h", -999, "big"),
        ("u16", "H", 65535, "big"),
        ("i32", "i", -2_000_000_000, "big"),
        ("u32", "I", 123_456_789, "big"),
        ("f32", "f", 0.25, "big"),
        ("f64", "d", -98765.4321, "big"),
        ("f32_le", "f", 1234.5, "little"),
        ("f64_le", "d", 3.141592653589793, "little"),
    ],
)
async def test_multi_register_writes_reach_the_tag_after_a_scan(plant, tag, fmt, value, order):
    await write_holding(plant, tag, words_of(fmt, value, order))
    await plant.wait_for(lambda: plant.db.value(tag) == value)
    assert value_of(fmt, await read_holding(plant, tag, len(words_of(fmt, value))), order) == value


async def test_single_register_write_echoes_the_request_and_applies_at_the_cycle_boundary(plant):
    response = await plant.client.write_register(plant.address("i16"), words_of("h", -321)[0], device_id=UNIT)
    assert not response.isError()
    assert response.registers == words_of("h", -321)  # FC6 echo
    await plant.wait_for(lambda: plant.db.value("i16") == -321)


async def test_coils_single_and_multiple(plant):
    client = plant.client
    response = await client.write_coil(plant.address("b_rw"), True, device_id=UNIT)
    assert not response.isError() and response.bits[0] is True
    await plant.wait_for(lambda: plant.db.value("b_rw") is True)
    assert (await client.read_coils(plant.address("b_rw"), count=1, device_id=UNIT)).bits[0] is True
    response = await client.write_coils(plant.address("b_rw"), [False], device_id=UNIT)
    assert not response.isError()
    await plant.wait_for(lambda: plant.db.value("b_rw") is False)


async def test_program_outputs_written_by_the_scan_are_read_back(plant):
    await write_holding(plant, "setpoint", words_of("d", 21.5))
    await plant.wait_for(lambda: plant.db.value("doubled") == 43.0)
    assert value_of("d", await read_input(plant, "doubled", 4)) == 43.0
    first = value_of("I", await read_input(plant, "scans", 2))
    await plant.next_cycles(3)
    assert value_of("I", await read_input(plant, "scans", 2)) > first


async def test_one_read_spanning_many_tags(plant):
    # i16 .. f64 are packed one after another from address 0 in declaration order.
    start = plant.address("i16")
    assert start == 0
    end = plant.adapter.map.by_tag["f64"].end
    response = await plant.client.read_holding_registers(start, count=end - start, device_id=UNIT)
    assert not response.isError()
    registers = response.registers
    assert value_of("h", registers[0:1]) == -5
    assert value_of("H", registers[1:2]) == 65000
    assert value_of("i", registers[2:4]) == -70000
    assert value_of("I", registers[4:6]) == 4000000000
    assert value_of("f", registers[6:8]) == 1.5
    assert value_of("d", registers[8:12]) == 2.25


async def test_a_125_register_read_is_served(tmp_path):
    yaml = "version: 1\ntags:\n" + "".join(f"  v{i:03d}: {{type: uint16, initial: {i}}}\n" for i in range(130))
    running = await start_plant(tmp_path, yaml + "servers:\n  modbus: {}\n")
    try:
        response = await running.client.read_holding_registers(0, count=125, device_id=1)
        assert not response.isError()
        assert response.registers == list(range(125))
    finally:
        await stop_plant(running)


async def test_system_tags_are_served_in_the_system_block(plant):
    cycles = plant.adapter.map.by_tag["_sys.fast.cycles"]
    assert cycles.address >= 60000
    await plant.wait_for(lambda: plant.db.value("_sys.fast.cycles") > 0)
    response = await plant.client.read_input_registers(cycles.address, count=2, device_id=UNIT)
    assert value_of("I", response.registers) > 0
    state = plant.adapter.map.by_tag["_sys.state"]
    response = await plant.client.read_input_registers(state.address, count=state.words, device_id=UNIT)
    text = b"".join(w.to_bytes(2, "big") for w in response.registers).rstrip(b"\0").decode()
    assert text == "RUNNING"
