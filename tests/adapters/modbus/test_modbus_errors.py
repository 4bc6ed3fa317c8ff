"""Every Modbus exception path, and that a rejected request never applies anything."""

from __future__ import annotations

import logging
import struct

import pytest
from modbus_helpers import mbap, raw_request, start_plant, stop_plant, value_of, words_of
from pymodbus.constants import ExcCodes

from softplc.adapters.modbus.server import ModbusAdapter
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.app.runtime import AdapterError, Runtime

PLANT = """
version: 1
tags:
  flag:      {type: bool}
  flag_ro:   {type: bool, access: ro}
  i16:       {type: int16, min: -1000, max: 1000, initial: 5}
  u16:       {type: uint16, initial: 10}
  i32:       {type: int32, initial: 20}
  f64:       {type: float64, min: 0, max: 100, initial: 50}
  tenths:    {type: uint16, initial: 3, modbus: {scale: 10}}
  level:     {type: float32, min: 0, max: 100, initial: 1, modbus: {scale: 100}}
  text:      {type: string, initial: "abc", modbus: {words: 2}}
  ro_num:    {type: uint16, access: ro, initial: 7, modbus: {table: holding, address: 200}}
  bool_reg:  {type: bool, modbus: {table: holding, address: 201}}
  far:       {type: int16, modbus: {address: 300}}
tasks:
  fast: {interval: 10ms}
servers:
  modbus: {unit_id: 1}
"""


@pytest.fixture
async def plant(tmp_path):
    running = await start_plant(tmp_path, PLANT)
    yield running
    await stop_plant(running)


def exception_code(response) -> int:
    assert response.isError(), f"expected an exception response, got {response}"
    return response.exception_code


async def assert_unchanged(plant, values: dict) -> None:
    """After two more scan cycles (journal applied), the tags still hold `values`."""
    await plant.next_cycles(2)
    assert {name: plant.db.value(name) for name in values} == values


# -- 02 illegal data address ---------------------------------------------------------------


async def test_reading_unmapped_addresses_is_illegal_address(plant):
    client = plant.client
    end = plant.adapter.map.by_tag["text"].end  # last auto-allocated holding register + 1
    assert exception_code(await client.read_holding_registers(end, count=1)) == ExcCodes.ILLEGAL_ADDRESS
    # a range that starts mapped and runs into the gap
    assert exception_code(await client.read_holding_registers(end - 1, count=2)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.read_holding_registers(302, count=1)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.read_input_registers(0, count=1)) == ExcCodes.ILLEGAL_ADDRESS  # no user input registers
    # coils are checked bit by bit: coil 1 is unmapped although it shares a 16-bit word with coil 0
    assert not (await client.read_coils(0, count=1)).isError()
    assert exception_code(await client.read_coils(1, count=1)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.read_coils(0, count=2)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.read_discrete_inputs(1, count=1)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.write_coil(1, True)) == ExcCodes.ILLEGAL_ADDRESS


async def test_writing_a_read_only_tag_is_illegal_address(plant):
    address = plant.address("ro_num")
    assert exception_code(await plant.client.write_register(address, 99)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await plant.client.write_registers(address, [99, 1])) == ExcCodes.ILLEGAL_ADDRESS
    await assert_unchanged(plant, {"ro_num": 7, "bool_reg": False})


async def test_writing_part_of_a_multi_register_value_is_illegal_address(plant):
    client, i32 = plant.client, plant.address("i32")
    assert exception_code(await client.write_register(i32, 0)) == ExcCodes.ILLEGAL_ADDRESS
    assert exception_code(await client.write_register(i32 + 1, 0)) == ExcCodes.ILLEGAL_ADDRESS
    f64 = plant.address("f64")
    assert exception_code(await client.write_registers(f64, [0, 0])) == ExcCodes.ILLEGAL_ADDRESS
    # whole u16, whole i32, and half of f64
    u16 = plant.address("u16")
    assert exception_code(await client.write_registers(u16, [1, 0, 1, 0, 0])) == ExcCodes.ILLEGAL_ADDRESS
    await assert_unchanged(plant, {"u16": 10, "i32": 20, "f64": 50.0})
    # reading half a value is the client's business and is allowed
    assert not (await client.read_holding_registers(i32 + 1, count=1)).isError()


# -- 03 illegal data value -----------------------------------------------------------------


async def test_out_of_range_is_illegal_value_and_nothing_is_applied(plant):
    client = plant.client
    assert exception_code(await client.write_register(plant.address("i16"), words_of("h", 2000)[0])) == ExcCodes.ILLEGAL_VALUE
    assert exception_code(await client.write_registers(plant.address("f64"), words_of("d", 100.5))) == ExcCodes.ILLEGAL_VALUE
    assert exception_code(await client.write_registers(plant.address("f64"), words_of("d", float("nan")))) == ExcCodes.ILLEGAL_VALUE
    assert exception_code(await client.write_register(plant.address("level"), 10001)) == ExcCodes.ILLEGAL_VALUE  # 100.01 %
    await assert_unchanged(plant, {"i16": 5, "f64": 50.0, "level": 1.0})


async def test_type_violations_are_illegal_value(plant):
    client = plant.client
    assert exception_code(await client.write_register(plant.address("bool_reg"), 2)) == ExcCodes.ILLEGAL_VALUE
    assert exception_code(await client.write_register(plant.address("tenths"), 123)) == ExcCodes.ILLEGAL_VALUE  # 12.3 in a uint16
    text = plant.address("text")
    assert exception_code(await client.write_registers(text, [0xC328, 0])) == ExcCodes.ILLEGAL_VALUE  # invalid UTF-8
    assert exception_code(await client.write_registers(text, [0x4100, 0x4100])) == ExcCodes.ILLEGAL_VALUE  # NUL inside
    await assert_unchanged(plant, {"bool_reg": False, "tenths": 3, "text": "abc"})
    # the same registers with valid contents are accepted
    assert not (await client.write_register(plant.address("bool_reg"), 1)).isError()
    assert not (await client.write_register(plant.address("tenths"), 120)).isError()
    await plant.wait_for(lambda: plant.db.value("bool_reg") is True and plant.db.value("tenths") == 12)


async def test_a_multi_tag_write_with_one_bad_tag_applies_nothing(plant):
    client = plant.client
    start = plant.address("i16")
    good_then_bad = words_of("h", 7) + words_of("H", 11) + words_of("i", 21) + words_of("d", 500.0)  # f64 max 100
    assert exception_code(await client.write_registers(start, good_then_bad)) == ExcCodes.ILLEGAL_VALUE
    bad_then_good = words_of("h", 5000) + words_of("H", 11) + words_of("i", 21) + words_of("d", 60.0)
    assert exception_code(await client.write_registers(start, bad_then_good)) == ExcCodes.ILLEGAL_VALUE
    await assert_unchanged(plant, {"i16": 5, "u16": 10, "i32": 20, "f64": 50.0})
    all_good = words_of("h", 7) + words_of("H", 11) + words_of("i", 21) + words_of("d", 60.0)
    assert not (await client.write_registers(start, all_good)).isError()
    await plant.wait_for(lambda: (plant.db.value("i16"), plant.db.value("u16"), plant.db.value("i32"), plant.db.value("f64")) == (7, 11, 21, 60.0))


@pytest.mark.parametrize(
    ("name", "pdu", "function"),
    [
        ("FC3 quantity 0", struct.pack(">BHH", 3, 0, 0), 3),
        ("FC3 quantity 126", struct.pack(">BHH", 3, 0, 126), 3),
        ("FC4 quantity 0", struct.pack(">BHH", 4, 0, 0), 4),
        ("FC1 quantity 2001", struct.pack(">BHH", 1, 0, 2001), 1),
        ("FC2 quantity 0", struct.pack(">BHH", 2, 0, 0), 2),
        ("FC5 value 0x1234", struct.pack(">BHH", 5, 0, 0x1234), 5),
        ("FC15 byte count too small", struct.pack(">BHHB", 15, 0, 9, 1) + b"\x01", 15),
        # 124 registers do not fit in a Modbus TCP frame (253-byte PDU): the largest legal frame
        # announcing them is answered 03; a longer one is a framing error (test_modbus_framing).
        ("FC16 quantity 124", struct.pack(">BHHB", 16, 0, 124, 248) + b"\0" * 247, 16),
        ("FC16 byte count mismatch", struct.pack(">BHHB", 16, 0, 2, 2) + b"\0\x01", 16),
        ("FC23 write quantity 122", struct.pack(">BHHHHB", 23, 0, 1, 0, 122, 244) + b"\0" * 243, 23),
    ],
)
async def test_malformed_quantities_get_the_function_exception_03(plant, name, pdu, function):
    answer = await raw_request(plant.port, mbap(7, 1, pdu))
    assert answer[0:2] == (7).to_bytes(2, "big")  # transaction id echoed
    assert answer[7] == function | 0x80, f"{name}: {answer.hex()}"
    assert answer[8] == ExcCodes.ILLEGAL_VALUE, f"{name}: {answer.hex()}"


async def test_read_write_multiple_and_mask_write_are_validated_too(plant):
    client = plant.client
    i16 = plant.address("i16")
    response = await client.readwrite_registers(read_address=i16, read_count=1, write_address=i16, values=[words_of("h", 9)[0]])
    assert not response.isError()
    await plant.wait_for(lambda: plant.db.value("i16") == 9)
    response = await client.readwrite_registers(read_address=i16, read_count=1, write_address=i16, values=[words_of("h", 9999)[0]])
    assert exception_code(response) == ExcCodes.ILLEGAL_VALUE
    assert exception_code(await client.mask_write_register(address=plant.address("i32"), and_mask=0, or_mask=1)) == ExcCodes.ILLEGAL_ADDRESS
    await assert_unchanged(plant, {"i16": 9, "i32": 20})


# -- 04, unknown unit ids, ports -------------------------------------------------------------


async def test_an_internal_failure_answers_04_and_the_server_keeps_serving(plant, caplog):
    # A runtime-internal writer bypassing validation (db.commit) leaves a value its encoding cannot carry.
    plant.db.commit({"u16": "not a number"})
    with caplog.at_level(logging.ERROR, logger="softplc.adapters.modbus.server"):
        response = await plant.client.read_holding_registers(plant.address("u16"), count=1)
    assert exception_code(response) == ExcCodes.DEVICE_FAILURE
    assert "Modbus request (function 3" in caplog.text
    plant.db.commit({"u16": 12})
    response = await plant.client.read_holding_registers(plant.address("u16"), count=1)
    assert response.registers == [12]


async def test_unknown_unit_ids_are_rejected_cleanly(plant, caplog):
    client = plant.client
    with caplog.at_level(logging.DEBUG):
        for unit in (0, 2, 247, 255):
            assert exception_code(await client.read_holding_registers(0, count=1, device_id=unit)) == ExcCodes.GATEWAY_NO_RESPONSE
            assert exception_code(await client.write_register(plant.address("i16"), 1, device_id=unit)) == ExcCodes.GATEWAY_NO_RESPONSE
            assert exception_code(await client.read_coils(0, count=1, device_id=unit)) == ExcCodes.GATEWAY_NO_RESPONSE
        assert not (await client.read_holding_registers(0, count=1, device_id=1)).isError()
    assert "Traceback" not in caplog.text
    assert [r for r in caplog.records if r.levelno >= logging.WARNING] == []
    await assert_unchanged(plant, {"i16": 5})


async def test_port_in_use_is_a_clear_adapter_error(plant, tmp_path):
    settings = ModbusSettings(enabled=True, host="127.0.0.1", port=plant.port, unit_id=1)
    second = Runtime(plant.runtime.config, state_dir=tmp_path / "second")
    second.add_adapter(ModbusAdapter(plant.runtime.config, settings))
    with pytest.raises(AdapterError, match="port in use"):
        await second.start()
    await second.stop()
    # the first server is unaffected
    assert value_of("h", (await plant.client.read_holding_registers(plant.address("i16"), count=1)).registers) == 5
