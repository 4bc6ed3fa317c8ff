"""FC43 / MEI type 14, Read Device Identification, answered with softplc's real name and version.

pymodbus answers this request from a process-wide control block that says "Pymodbus" unless
told otherwise, and without a unit id check. This request class (served instead) follows the
Modbus Application Protocol v1.1b3, section 6.21, at conformity level 0x82 (regular
identification, stream and individual access):

    0x00 VendorName          softplc
    0x01 ProductCode         softplc
    0x02 MajorMinorRevision  softplc's version, e.g. 0.1.0
    0x04 ProductName         softplc soft PLC
    0x06 UserApplicationName the plant's `plant: name:` (left out when empty)

Read device id code 01 (basic) streams objects 0-2, 02 and 03 (regular; a device answers a
higher level at its own level) objects 0-6; an object id the stream does not hold restarts it
at object 0; 04 reads one object (02 illegal data address if it does not exist); other codes
are 03. MEI types other than 14 (e.g. 13, CANopen) are 01 illegal function.
"""

from __future__ import annotations

import struct
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.pdu import ExceptionResponse, ModbusPDU

from softplc import __version__
from softplc.adapters.modbus.requests import RequestGuard

FUNCTION_CODE = 0x2B
MEI_READ_DEVICE_ID = 0x0E
CONFORMITY = 0x82  # regular identification, stream and individual access
_BASIC, _REGULAR, _EXTENDED, _INDIVIDUAL = 1, 2, 3, 4
_LAST_OBJECT = {_BASIC: 0x02, _REGULAR: 0x7F, _EXTENDED: 0x7F}  # we serve no extended objects
_MAX_PDU = 253
_HEADER = 7  # function, MEI type, read code, conformity, more follows, next object id, count
_MAX_VALUE = 200  # bytes per object, so any single object fits in one response


def device_objects(plant_name: str = "") -> dict[int, bytes]:
    """The identification objects softplc serves (ASCII, as the spec wants; others become '?')."""
    objects = {0x00: "softplc", 0x01: "softplc", 0x02: __version__, 0x04: "softplc soft PLC"}
    if plant_name:
        objects[0x06] = plant_name
    return {object_id: text.encode("ascii", "replace")[:_MAX_VALUE] for object_id, text in objects.items()}


def identification_request(guard: RequestGuard, objects: dict[int, bytes]) -> type[ModbusPDU]:
    """The FC43 request class serving `objects`, checked by `guard` (unit id first)."""

    class ReadDeviceIdentification(ModbusPDU):
        """FC43 / MEI 14 with softplc's identity."""

        function_code = FUNCTION_CODE

        def __init__(self) -> None:
            super().__init__()
            self.mei_type = 0
            self.read_code = 0
            self.object_id = 0

        def decode(self, data: bytes) -> None:
            self.mei_type = data[0]
            if self.mei_type == MEI_READ_DEVICE_ID:
                self.read_code, self.object_id = struct.unpack(">BB", data[1:3])

        async def datastore_update(self, context: Any, device_id: int) -> ModbusPDU:
            code = guard.check_unit(device_id)
            if code is None and self.mei_type != MEI_READ_DEVICE_ID:
                code = ExcCodes.ILLEGAL_FUNCTION
            if code is None:
                answer = identification_answer(objects, self.read_code, self.object_id)
                if isinstance(answer, bytes):
                    return RawResponse(FUNCTION_CODE, answer)
                code = answer
            return ExceptionResponse(FUNCTION_CODE, code)

    return ReadDeviceIdentification


def identification_answer(objects: dict[int, bytes], read_code: int, object_id: int) -> bytes | ExcCodes:
    """The response data after the function code (MEI type onwards), or an exception code."""
    if read_code == _INDIVIDUAL:
        if object_id not in objects:
            return ExcCodes.ILLEGAL_ADDRESS
        chosen = [object_id]
        level = _INDIVIDUAL
    elif read_code in _LAST_OBJECT:
        level = min(read_code, _REGULAR)
        stream = [oid for oid in sorted(objects) if oid <= _LAST_OBJECT[level]]
        chosen = stream[stream.index(object_id) :] if object_id in stream else stream
    else:
        return ExcCodes.ILLEGAL_VALUE
    body = b""
    count = 0
    more, next_object = 0x00, 0x00
    for oid in chosen:
        item = struct.pack(">BB", oid, len(objects[oid])) + objects[oid]
        if _HEADER + len(body) + len(item) > _MAX_PDU:
            more, next_object = 0xFF, oid  # the client asks again from next_object
            break
        body += item
        count += 1
    return struct.pack(">BBBBBB", MEI_READ_DEVICE_ID, level, CONFORMITY, more, next_object, count) + body


class RawResponse(ModbusPDU):
    """A response whose data is already encoded."""

    def __init__(self, function_code: int, data: bytes) -> None:
        super().__init__()
        self.function_code = function_code
        self.data = data

    def encode(self) -> bytes:
        return self.data
