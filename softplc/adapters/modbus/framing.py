"""Modbus TCP framing: cutting a connection's byte stream into requests at MBAP headers.

The MBAP header (Modbus Messaging on TCP/IP Implementation Guide v1.0b, 3.1.3) is the only
frame marker a Modbus TCP stream has:

    transaction id  2 bytes  copied into the response
    protocol id     2 bytes  0 = Modbus; anything else is not a Modbus request
    length          2 bytes  the bytes that follow: unit id + PDU, so 2 (a function code
                             alone) to 254 (a 260-byte ADU)
    unit id         1 byte

Once one header is wrong, nothing in the stream says where the next frame starts: a byte
pattern that looks like a header may as well be inside the garbage. So a wrong header is a
`FramingError` and the connection is closed (what PLCs do); the client reconnects and its
next request is answered at once. pymodbus 3.16 instead kept the bad bytes at the head of its
buffer and answered nothing until the buffer overflowed ~500 bytes later.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER_SIZE = 7  # transaction id, protocol id, length, unit id
MIN_LENGTH = 2  # unit id + function code
MAX_LENGTH = 254  # unit id + the largest PDU (253 bytes)
MAX_FRAME = 6 + MAX_LENGTH


class FramingError(Exception):
    """The bytes received are not a Modbus TCP frame; `field` names what is wrong."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class Frame:
    """One complete request: the MBAP fields a response needs and the PDU (function code + data)."""

    transaction_id: int
    unit_id: int
    pdu: bytes


class FrameBuffer:
    """The bytes received on one connection, taken out a frame at a time."""

    def __init__(self) -> None:
        self._data = bytearray()

    def __len__(self) -> int:
        return len(self._data)

    def feed(self, data: bytes) -> None:
        self._data += data

    def clear(self) -> None:
        self._data.clear()

    def next_frame(self) -> Frame | None:
        """The next complete frame, or None until more bytes arrive; raises FramingError.

        Each header field is checked as soon as its bytes are there, so garbage is recognised
        without waiting for the frame length it seems to announce.
        """
        data = self._data
        if len(data) >= 4 and (protocol := int.from_bytes(data[2:4], "big")) != 0:
            raise FramingError("protocol id", f"protocol id {protocol:#06x} in the MBAP header (Modbus TCP is 0)")
        if len(data) < 6:
            return None
        length = int.from_bytes(data[4:6], "big")
        if not MIN_LENGTH <= length <= MAX_LENGTH:
            raise FramingError("length",
                               f"length field {length} in the MBAP header (a request has {MIN_LENGTH}..{MAX_LENGTH})")
        end = 6 + length
        if len(data) < end:
            return None
        frame = Frame(int.from_bytes(data[0:2], "big"), data[6], bytes(data[HEADER_SIZE:end]))
        del data[:end]
        return frame

    def describe_partial(self) -> str:
        """What the buffer holds of an incomplete frame (for the message when it never completes)."""
        if len(self._data) < 6:
            return f"{len(self._data)} bytes of an MBAP header"
        return f"{len(self._data)} of the {6 + int.from_bytes(self._data[4:6], 'big')} bytes its header announces"
