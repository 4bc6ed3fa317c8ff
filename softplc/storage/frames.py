"""The frames between the runtime and its writer's process: a 4-byte big-endian length, then a pickle."""

from __future__ import annotations

import pickle
import struct
from typing import IO, Any

FRAME = struct.Struct(">I")


def frame(message: Any) -> bytes:
    """`message` as one frame."""
    data = pickle.dumps(message, 5)
    return FRAME.pack(len(data)) + data


def send(stream: IO[bytes], message: Any) -> None:
    """Write one frame and flush it."""
    stream.write(frame(message))
    stream.flush()


def receive(stream: IO[bytes]) -> Any:
    """The next frame's message, or None at the end of the stream."""
    header = stream.read(FRAME.size)
    if len(header) < FRAME.size:
        return None
    (length,) = FRAME.unpack(header)
    data = stream.read(length)
    return pickle.loads(data) if len(data) == length else None
