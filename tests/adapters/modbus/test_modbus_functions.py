"""Which function codes are served: the ten data codes and FC43/14; everything else is 01, unit id first."""

from __future__ import annotations

import asyncio
import struct

import pytest
from modbus_helpers import mbap, raw_request, start_plant, stop_plant
from pymodbus.constants import DeviceInformation, ExcCodes

import softplc
from softplc.adapters.modbus.identification import identification_answer

PLANT = """
version: 1
plant: {name: Test line 3}
tags:
  flag: {type: bool}
  u16: {type: uint16, initial: 10}
tasks:
  fast: {interval: 10ms}
servers:
  modbus: {unit_id: 1}
"""

# Requests pymodbus itself would answer with canned or fake data, and codes nobody defines.
UNSERVED = [
    ("FC7 read exception status", b"\x07"),
    ("FC8 diagnostics, return query data", b"\x08\x00\x00\x12\x34"),
    ("FC8 diagnostics, restart communications", b"\x08\x00\x01\x00\x00"),
    ("FC11 get comm event counter", b"\x0b"),
    ("FC12 get comm event log", b"\x0c"),
    ("FC17 report server id", b"\x11"),
    ("FC20 read file record", b"\x14\x07\x06\x00\x01\x00\x00\x00\x01"),
    ("FC21 write file record", b"\x15\x09\x06\x00\x01\x00\x00\x00\x01\x12\x34"),
    ("FC24 read FIFO queue", b"\x18\x00\x00"),
    ("FC43 MEI 13 CANopen", b"\x2b\x0d\x00\x00"),
    ("0x41 undefined", b"\x41\x00\x00"),
    ("0x7F undefined", b"\x7f"),
    ("0x00 invalid", b"\x00"),
]


@pytest.fixture
async def plant(tmp_path):
    running = await start_plant(tmp_path, PLANT)
    yield running
    await stop_plant(running)


def pdu_of(answer: bytes) -> bytes:
    return answer[7:]


@pytest.mark.parametrize(("name", "pdu"), UNSERVED, ids=[name for name, _ in UNSERVED])
async def test_unserved_function_codes_are_illegal_function_with_the_spec_function_byte(plant, name, pdu):
    function = pdu[0]
    answer = await raw_request(plant.port, mbap(7, 1, pdu))
    assert answer[0:2] == b"\x00\x07" and answer[6] == 1  # transaction and unit id echoed
    assert pdu_of(answer) == bytes([function | 0x80, ExcCodes.ILLEGAL_FUNCTION]), f"{name}: {answer.hex()}"


@pytest.mark.parametrize(("name", "pdu"), UNSERVED + [("FC43/14 device identification", b"\x2b\x0e\x01\x00"), ("FC3 read", b"\x03\x00\x00\x00\x01")])
async def test_a_foreign_unit_id_is_0B_for_every_function_code(plant, name, pdu):
    answer = await raw_request(plant.port, mbap(8, 9, pdu))
    assert pdu_of(answer) == bytes([pdu[0] | 0x80, ExcCodes.GATEWAY_NO_RESPONSE]), f"{name}: {answer.hex()}"


async def test_write_file_record_writes_nothing_and_fifo_has_no_fake_data(plant):
    client = plant.client
    response = await client.read_fifo_queue(address=0)
    assert response.isError() and response.exception_code == ExcCodes.ILLEGAL_FUNCTION
    response = await client.report_device_id()
    assert response.isError() and response.exception_code == ExcCodes.ILLEGAL_FUNCTION
    # the connection stays usable
    assert (await client.read_holding_registers(plant.address("u16"), count=1)).registers == [10]


@pytest.mark.parametrize(
    ("name", "pdu", "function"),
    [("FC3 without quantity", b"\x03\x00", 3), ("FC6 without value", b"\x06\x00\x00", 6), ("FC22 without or-mask", b"\x16\x00\x00\xff\xff", 22), ("FC43 without MEI type", b"\x2b", 43), ("FC43/14 without object id", b"\x2b\x0e\x01", 43)],
)
async def test_a_served_request_too_short_to_decode_is_illegal_value(plant, name, pdu, function):
    answer = await raw_request(plant.port, mbap(9, 1, pdu))
    assert pdu_of(answer) == bytes([function | 0x80, ExcCodes.ILLEGAL_VALUE]), f"{name}: {answer.hex()}"


async def test_unknown_function_then_a_read_on_the_same_connection(plant):
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        for transaction in range(1, 4):
            writer.write(mbap(transaction, 1, b"\x41\x00\x00"))
            await writer.drain()
            answer = await asyncio.wait_for(reader.readexactly(9), 2.0)
            assert answer[0:2] == transaction.to_bytes(2, "big") and answer[7:] == b"\xc1\x01"
        writer.write(mbap(9, 1, struct.pack(">BHH", 3, plant.address("u16"), 1)))
        await writer.drain()
        answer = await asyncio.wait_for(reader.readexactly(11), 2.0)
        assert answer[7:] == b"\x03\x02\x00\x0a"
    finally:
        writer.close()


# -- FC43 / MEI 14: read device identification ------------------------------------------------


async def test_device_identification_names_softplc_its_version_and_the_plant(plant):
    client = plant.client
    basic = await client.read_device_information(read_code=DeviceInformation.BASIC, object_id=0)
    assert not basic.isError()
    assert basic.information == {0: b"softplc", 1: b"softplc", 2: softplc.__version__.encode()}
    assert basic.conformity == 0x82 and basic.more_follows == 0
    regular = await client.read_device_information(read_code=DeviceInformation.REGULAR, object_id=0)
    assert regular.information == {0: b"softplc", 1: b"softplc", 2: softplc.__version__.encode(), 4: b"softplc soft PLC", 6: b"Test line 3"}
    # a stream starting at an object id it does not hold restarts at object 0
    assert (await client.read_device_information(read_code=DeviceInformation.BASIC, object_id=5)).information == basic.information
    # stream from object 2 onwards
    assert list((await client.read_device_information(read_code=DeviceInformation.REGULAR, object_id=2)).information) == [2, 4, 6]
    # extended is answered at the device's own (regular) level
    extended = await client.read_device_information(read_code=DeviceInformation.EXTENDED, object_id=0)
    assert extended.information == regular.information and extended.read_code == DeviceInformation.REGULAR


async def test_device_identification_individual_access_and_errors(plant):
    client = plant.client
    single = await client.read_device_information(read_code=DeviceInformation.SPECIFIC, object_id=6)
    assert single.information == {6: b"Test line 3"}
    missing = await client.read_device_information(read_code=DeviceInformation.SPECIFIC, object_id=3)  # no VendorUrl
    assert missing.isError() and missing.exception_code == ExcCodes.ILLEGAL_ADDRESS
    answer = await raw_request(plant.port, mbap(1, 1, b"\x2b\x0e\x05\x00"))  # read device id code 5
    assert pdu_of(answer) == b"\xab\x03"


async def test_a_long_plant_name_is_cut_to_200_bytes_and_served_whole(tmp_path):
    running = await start_plant(tmp_path, PLANT.replace("Test line 3", "P" * 300))
    try:
        single = await running.client.read_device_information(read_code=DeviceInformation.SPECIFIC, object_id=6)
        assert single.information == {6: b"P" * 200}
        regular = await running.client.read_device_information(read_code=DeviceInformation.REGULAR, object_id=0)
        assert regular.information[6] == b"P" * 200 and regular.more_follows == 0
    finally:
        await stop_plant(running)


def test_objects_that_do_not_fit_one_response_follow_in_the_next():
    objects = {0: b"V" * 130, 1: b"C" * 130, 2: b"1.0"}
    data = identification_answer(objects, DeviceInformation.BASIC, 0)
    assert isinstance(data, bytes) and len(data) + 1 <= 253  # + the function code
    assert data[3:6] == b"\xff\x01\x01"  # more follows, next object 1, one object
    data = identification_answer(objects, DeviceInformation.BASIC, 1)
    assert data[3:6] == b"\x00\x00\x02" and data[6:8] == bytes([1, 130])
