"""Request PDUs that check unit id, quantity and address before pymodbus touches the datastore.

pymodbus 3.16 on its own answers a quantity of 0 or above the limit with function 0x80 /
exception 01 (its decoder rejects the frame), an unknown unit id with 04 plus a traceback in
the log, and checks coil addresses only per 16-bit word. These subclasses (the only data
requests functions.RequestDecoder knows) follow the Modbus Application Protocol's order instead:

    unknown unit id      → 0x0B gateway target failed to respond (logged at debug, no traceback)
    quantity out of range → 03 illegal data value
    any address unmapped → 02 illegal data address
    then the datastore (the SimDevice action validates writes).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from typing import Any

from pymodbus.constants import ExcCodes, ModbusStatus
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.bit_message import (
    ReadCoilsRequest,
    ReadDiscreteInputsRequest,
    WriteMultipleCoilsRequest,
    WriteSingleCoilRequest,
)
from pymodbus.pdu.register_message import (
    MaskWriteRegisterRequest,
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    ReadWriteMultipleRegistersRequest,
    WriteMultipleRegistersRequest,
    WriteSingleRegisterRequest,
)
from pymodbus.pdu.utils import unpack_bitstring

from softplc.adapters.modbus.address_map import AddressMap, Table

log = logging.getLogger(__name__)

# (function code → table, maximum quantity) from the Modbus Application Protocol v1.1b3.
LIMITS: dict[int, tuple[Table, int]] = {
    1: (Table.COIL, 2000),
    2: (Table.DISCRETE_INPUT, 2000),
    3: (Table.HOLDING, 125),
    4: (Table.INPUT, 125),
    5: (Table.COIL, 1),
    6: (Table.HOLDING, 1),
    15: (Table.COIL, 1968),
    16: (Table.HOLDING, 123),
    22: (Table.HOLDING, 1),
    23: (Table.HOLDING, 125),
}


class RequestGuard:
    """The checks every data request passes before it reaches the datastore."""

    def __init__(self, address_map: AddressMap, unit_id: int) -> None:
        self.map = address_map
        self.unit_id = unit_id
        self._unknown_units: set[int] = set()

    def check_unit(self, device_id: int) -> ExcCodes | None:
        """0B for a unit id other than ours (the first check of every function code), else None."""
        if device_id == self.unit_id:
            return None
        if device_id not in self._unknown_units:
            self._unknown_units.add(device_id)  # say it once per unit id (at most 256), not per request
            log.debug("modbus: request for unit id %d, this server is unit %d", device_id, self.unit_id)
        return ExcCodes.GATEWAY_NO_RESPONSE

    def check(self, function_code: int, device_id: int, ranges: list[tuple[int, int]]) -> ExcCodes | None:
        """An exception code for a request touching (address, count) `ranges`, or None if it may proceed."""
        if (code := self.check_unit(device_id)) is not None:
            return code
        table, limit = LIMITS[function_code]
        for index, (_, count) in enumerate(ranges):
            # FC23's write part may carry at most 121 registers.
            maximum = 121 if function_code == 23 and index == 1 else limit
            if not 1 <= count <= maximum:
                return ExcCodes.ILLEGAL_VALUE
        for address, count in ranges:
            if self.map.covering(table, address, count) is None:
                return ExcCodes.ILLEGAL_ADDRESS
        return None


def guarded_requests(guard: RequestGuard) -> list[type[ModbusPDU]]:
    """Request classes bound to `guard`, one per data function code (see LIMITS)."""

    def make(base: type[ModbusPDU], ranges: Callable[[Any], list[tuple[int, int]]], decode: Callable[[Any, bytes], None] | None = None) -> type[ModbusPDU]:
        async def datastore_update(self: Any, context: Any, device_id: int) -> ModbusPDU:
            code = guard.check(self.function_code, device_id, ranges(self))
            if code is not None:
                return ExceptionResponse(self.function_code, code)
            return await base.datastore_update(self, context, device_id)  # type: ignore[misc]

        namespace: dict[str, Any] = {"datastore_update": datastore_update, "__doc__": f"{base.__name__} checked by softplc."}
        if decode is not None:
            namespace["decode"] = decode
        return type("Guarded" + base.__name__, (base,), namespace)

    return [
        make(ReadCoilsRequest, _count_range, _decode_address_count),
        make(ReadDiscreteInputsRequest, _count_range, _decode_address_count),
        make(ReadHoldingRegistersRequest, _count_range, _decode_address_count),
        make(ReadInputRegistersRequest, _count_range, _decode_address_count),
        make(WriteSingleCoilRequest, _count_range, _decode_single_coil),
        make(WriteSingleRegisterRequest, _single_range),
        make(WriteMultipleCoilsRequest, _coils_range, _decode_multiple_coils),
        make(WriteMultipleRegistersRequest, _registers_range),
        make(MaskWriteRegisterRequest, _single_range),
        make(ReadWriteMultipleRegistersRequest, _read_write_ranges, _decode_read_write),
    ]


def _count_range(request: Any) -> list[tuple[int, int]]:
    return [(request.address, request.count)]


def _single_range(request: Any) -> list[tuple[int, int]]:
    return [(request.address, 1)]


def _coils_range(request: Any) -> list[tuple[int, int]]:
    # A byte count that disagrees with the quantity or the payload is a bad quantity (03).
    byte_count = (request.count + 7) // 8
    consistent = request.byte_count == byte_count and request.data_byte_count == byte_count
    return [(request.address, request.count if consistent else 0)]


def _registers_range(request: Any) -> list[tuple[int, int]]:
    consistent = request.byte_count == request.count * 2 and request._payload_byte_count == request.byte_count
    return [(request.address, request.count if consistent else 0)]


def _read_write_ranges(request: Any) -> list[tuple[int, int]]:
    consistent = request.write_byte_count == request.write_count * 2 and request._payload_byte_count == request.write_byte_count
    return [(request.read_address, request.read_count), (request.write_address, request.write_count if consistent else 0)]


def _decode_address_count(self: Any, data: bytes) -> None:
    # Like pymodbus, minus verifyCount: a bad quantity must become exception 03, not a dropped frame.
    self.address, self.count = struct.unpack(">HH", data[:4])


def _decode_single_coil(self: Any, data: bytes) -> None:
    self.address, value = struct.unpack(">HH", data[:4])
    # FF00 and 0000 are the only valid values; anything else is answered with 03 by the guard.
    self.count = 1 if value in (ModbusStatus.ON, ModbusStatus.OFF) else 0
    self.bits = [value == ModbusStatus.ON]


def _decode_multiple_coils(self: Any, data: bytes) -> None:
    self.address, self.count, self.byte_count = struct.unpack(">HHB", data[0:5])
    self.data_byte_count = len(data) - 5
    self.bits = unpack_bitstring(data[5 : 5 + self.byte_count])[: self.count]


def _decode_read_write(self: Any, data: bytes) -> None:
    self.read_address, self.read_count, self.write_address, self.write_count, self.write_byte_count = struct.unpack(">HHHHB", data[:9])
    self._payload_byte_count = len(data) - 9
    self.write_registers = [struct.unpack(">H", data[i : i + 2])[0] for i in range(9, min(len(data), self.write_byte_count + 9) - 1, 2)]
