"""The sync link's wire: length-prefixed MessagePack frames over mutual TLS, and the messages they carry.

    standby → active   ["hello", VERSION, member, config_hash, nonce, last_epoch]
    active → standby   ["welcome", VERSION, member, config_hash, nonce, epoch]  |  ["refuse", why]
    active → standby   ["data", epoch, counter, payload]     payload: a state or journal message (plant.replication)
    standby → active   ["ack", sequence]                     the last state applied
    either             ["refuse", why]                       before closing: what was refused and why

The welcome echoes the standby's fresh nonce, and every data frame carries the active's epoch
and a counter that starts at 1 on each connection and grows by exactly 1: a recorded frame played
again, or one from an older active, is out of place and refused. A frame longer than
MAX_FRAME, not MessagePack, or not of the shapes above is refused the same way.
"""

from __future__ import annotations

import asyncio
import struct
from typing import Any

VERSION = 1
MAX_FRAME = 256 * 1024 * 1024  # a full state of a very large plant fits; anything bigger is refused
_LENGTH = struct.Struct(">I")


class LinkRefused(Exception):
    """A message (or a peer) refused: the reason is reported, nothing of it is applied."""


def encode(message: Any) -> bytes:
    import msgpack

    body = msgpack.packb(message, use_bin_type=True)
    return _LENGTH.pack(len(body)) + body


async def read_message(reader: asyncio.StreamReader) -> Any:
    """The next message; raises LinkRefused for a malformed frame, IncompleteReadError when the peer is gone."""
    import msgpack

    (length,) = _LENGTH.unpack(await reader.readexactly(_LENGTH.size))
    if length > MAX_FRAME:
        raise LinkRefused(f"a frame of {length} bytes (at most {MAX_FRAME})")
    body = await reader.readexactly(length)
    try:
        message = msgpack.unpackb(body, raw=False, strict_map_key=True)
    except Exception as error:  # whatever the bytes are, they are not a message
        raise LinkRefused(f"not MessagePack: {type(error).__name__}") from None
    if not isinstance(message, list) or not message or not isinstance(message[0], str):
        raise LinkRefused("not a message (a list starting with its kind)")
    return message


def expect(message: Any, kind: str, length: int) -> list[Any]:
    """`message` if it is a `kind` message of `length` items; raises LinkRefused (a `refuse` says why)."""
    if message[0] == "refuse" and len(message) == 2:
        raise LinkRefused(f"the peer refused: {message[1]}")
    if message[0] != kind or len(message) != length:
        raise LinkRefused(f"expected {kind!r}, got {str(message[0])[:40]!r} of {len(message)} items")
    return message


def check_hello(message: Any) -> tuple[str, str, bytes, int]:
    _, version, member, config_hash, nonce, epoch = expect(message, "hello", 6)
    if version != VERSION:
        raise LinkRefused(f"sync link version {version!r}, this runtime speaks {VERSION}")
    if not isinstance(member, str) or not isinstance(config_hash, str) or not isinstance(nonce, bytes) or len(nonce) != 16:
        raise LinkRefused("a malformed hello")
    if not isinstance(epoch, int) or isinstance(epoch, bool):
        raise LinkRefused("a malformed hello")
    return member, config_hash, nonce, epoch


def check_welcome(message: Any, nonce: bytes) -> tuple[str, str, int]:
    _, version, member, config_hash, echoed, epoch = expect(message, "welcome", 6)
    if version != VERSION:
        raise LinkRefused(f"sync link version {version!r}, this runtime speaks {VERSION}")
    if echoed != nonce:
        raise LinkRefused("the welcome does not answer this connection's hello (a replayed welcome)")
    if not isinstance(member, str) or not isinstance(config_hash, str) or not isinstance(epoch, int) or isinstance(epoch, bool):
        raise LinkRefused("a malformed welcome")
    return member, config_hash, epoch


def check_data(message: Any, epoch: int, counter: int) -> Any:
    """The payload of the next data frame; raises LinkRefused unless it is the expected one."""
    _, frame_epoch, frame_counter, payload = expect(message, "data", 4)
    if frame_epoch != epoch:
        raise LinkRefused(f"a frame of epoch {frame_epoch!r} on a link of epoch {epoch} (an older active's?)")
    if frame_counter != counter:
        raise LinkRefused(f"frame {frame_counter!r} where {counter} was due (replayed, lost or reordered)")
    return payload
