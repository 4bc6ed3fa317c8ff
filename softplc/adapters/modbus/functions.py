"""Which function codes the server answers: the decoder that turns a request frame into a PDU.

pymodbus 3.16's own server decoder knows about 30 requests and answers those softplc does not
back with data (FC7, 8, 11, 12, 17, 20, 21, 24, 43) with canned or fake results and without
a unit id check; for a function code it does not know it answers function 0x80 instead of
0x80 | function. `RequestDecoder` replaces it (ModbusBaseServer.decoder, read by every new
connection) and knows only the requests softplc serves:

    a served function code        → its request class (requests.py, identification.py)
    any other function code       → IllegalFunction: fc | 0x80 with 01, or 0B for a foreign unit id
    a served code whose PDU is too short to decode
                                  → MalformedRequest: fc | 0x80 with 03, or 0B for a foreign unit id

So every frame gets an answer with the spec's function byte, and the unit id check comes first
for every function code.
"""

from __future__ import annotations

import logging
import struct
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU

from softplc.adapters.modbus.requests import RequestGuard

log = logging.getLogger(__name__)


class _Rejected(ModbusPDU):
    """A request answered with an exception whatever it asks (after the unit id check)."""

    exception = ExcCodes.ILLEGAL_FUNCTION

    def __init__(self, function_code: int, guard: RequestGuard) -> None:
        super().__init__()
        self.function_code = function_code
        self._guard = guard

    async def datastore_update(self, context: Any, device_id: int) -> ModbusPDU:
        code = self._guard.check_unit(device_id) or self.exception
        return ExceptionResponse(self.function_code, code)


class IllegalFunction(_Rejected):
    """A function code softplc does not serve: exception 01."""

    exception = ExcCodes.ILLEGAL_FUNCTION


class MalformedRequest(_Rejected):
    """A served function code with a PDU too short to decode: exception 03 (spec: wrong implied length)."""

    exception = ExcCodes.ILLEGAL_VALUE


class RequestDecoder(DecodePDU):
    """Server-side decoder knowing exactly `requests` (one class per function code)."""

    def __init__(self, requests: list[type[ModbusPDU]], guard: RequestGuard) -> None:
        super().__init__(is_server=True)
        # Instance tables: pymodbus's class-level tables hold every request it implements.
        self.pdu_table = {request.function_code: (request, request) for request in requests}
        self.pdu_sub_table = {}
        self._guard = guard
        self._unserved: set[int] = set()

    @property
    def function_codes(self) -> list[int]:
        """The function codes served, in order."""
        return sorted(self.pdu_table)

    def decode(self, frame: bytes) -> ModbusPDU | None:
        """The request in `frame` (function code + data); never None for a non-empty frame."""
        if not frame:
            return None
        function_code = frame[0]
        entry = self.pdu_table.get(function_code)
        if entry is None:
            if function_code not in self._unserved:
                self._unserved.add(function_code)  # at most 256 entries: say it once per code
                log.debug("modbus: function code %d is not served (answered with exception 01)", function_code)
            return IllegalFunction(function_code, self._guard)
        pdu = entry[0]()
        try:
            pdu.decode(frame[1:])
        except (ValueError, IndexError, struct.error):
            log.debug("modbus: function %d request too short to decode (%d bytes): exception 03", function_code, len(frame))
            return MalformedRequest(function_code, self._guard)
        return pdu
