"""Store and forward: data messages kept on disk while the primary host (or the broker) is away.

Each message is a record `(device, payload)` appended to the newest of a few segment files
(`00000001.spool`, ...) under the plant's state directory; past `max_size` the oldest segment is
dropped (and counted), so the store stays bounded whatever the outage. Forwarding reads the
oldest segment, hands its records over in order and deletes the file once all were sent. What
was forwarded is remembered in memory only: after a crash in the middle of forwarding, that
segment's records are forwarded again (at least once, never lost while they fit).

Records: 4-byte little-endian payload length, 2-byte device-id length, the device id (UTF-8),
the payload (a Sparkplug payload with metrics by name, no seq). A record cut short by a crash
ends its segment; the file is truncated there when the store opens.
"""

from __future__ import annotations

import logging
import struct
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

log = logging.getLogger(__name__)

HEADER = struct.Struct("<IH")
SUFFIX = ".spool"
MAX_RECORD = 64 * 1024 * 1024


@dataclass
class _Segment:
    path: Path
    size: int = 0
    records: int = 0


class Store:
    """See the module docstring."""

    def __init__(self, directory: Path, max_size: int) -> None:
        self.directory = directory
        self.max_size = max_size
        self.segment_size = max(16 * 1024, max_size // 16)
        self.dropped = 0  # records dropped because the store was full (or a disk error)
        self._segments: deque[_Segment] = deque()
        self._writer: BinaryIO | None = None
        self._forwarded = 0  # records of the oldest segment already handed over
        self._failing = False

    # -- what the edge node calls --------------------------------------------------------------

    def open(self) -> None:
        """Find the segments a previous run left (oldest first), cutting off a torn last record."""
        self.directory.mkdir(parents=True, exist_ok=True)
        for path in sorted(self.directory.glob(f"*{SUFFIX}")):
            segment = _Segment(path)
            good = 0
            for _, _, end in self._records(path):
                segment.records += 1
                good = end
            if good != path.stat().st_size:
                log.warning("Sparkplug store: %s ends in a torn record (a crash while writing): cut at byte %d", path, good)
                with path.open("r+b") as file:
                    file.truncate(good)
            segment.size = good
            if segment.records:
                self._segments.append(segment)
            else:
                path.unlink(missing_ok=True)

    @property
    def count(self) -> int:
        """Records waiting to be forwarded."""
        return sum(segment.records for segment in self._segments) - self._forwarded

    @property
    def size(self) -> int:
        return sum(segment.size for segment in self._segments)

    def append(self, device: str, payload: bytes) -> None:
        """Keep one message; drops the oldest segment when the store would outgrow `max_size`."""
        name = device.encode("utf-8")
        record = HEADER.pack(len(payload), len(name)) + name + payload
        try:
            segment = self._current(len(record))
            assert self._writer is not None
            self._writer.write(record)
            self._writer.flush()  # in the operating system's hands: survives a kill -9 of softplc
        except OSError as error:
            self.dropped += 1
            if not self._failing:
                self._failing = True
                log.warning("Sparkplug store: cannot write to %s (%s): data is dropped until it can", self.directory, error)
            return
        self._failing = False
        segment.size += len(record)
        segment.records += 1
        while self.size > self.max_size and len(self._segments) > 1:
            self._drop_oldest()

    def oldest(self) -> list[tuple[str, bytes]]:
        """The records of the oldest segment not yet forwarded, in order (empty when the store is empty)."""
        if not self._segments:
            return []
        if len(self._segments) == 1:
            self._close_writer()  # what is forwarded is never appended to any more
        segment = self._segments[0]
        return [(device, payload) for device, payload, _ in self._records(segment.path)][self._forwarded:]

    def forwarded(self, records: int) -> None:
        """`records` more of the oldest segment were sent; the segment goes once all were."""
        if not self._segments:
            return
        self._forwarded += records
        segment = self._segments[0]
        if self._forwarded >= segment.records:
            self._segments.popleft()
            self._forwarded = 0
            segment.path.unlink(missing_ok=True)

    def close(self) -> None:
        self._close_writer()

    # -- inside --------------------------------------------------------------------------------

    def _current(self, extra: int) -> _Segment:
        if self._writer is not None and self._segments and self._segments[-1].size + extra <= self.segment_size:
            return self._segments[-1]
        self._close_writer()
        number = int(self._segments[-1].path.stem) + 1 if self._segments else 1
        segment = _Segment(self.directory / f"{number:08d}{SUFFIX}")
        self.directory.mkdir(parents=True, exist_ok=True)
        self._writer = segment.path.open("ab")
        self._segments.append(segment)
        return segment

    def _close_writer(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def _drop_oldest(self) -> None:
        segment = self._segments.popleft()
        lost = segment.records - self._forwarded
        self._forwarded = 0
        self.dropped += lost
        segment.path.unlink(missing_ok=True)
        log.warning("Sparkplug store: full (%d bytes at most): the oldest %d data messages were dropped", self.max_size, lost)

    @staticmethod
    def _records(path: Path) -> Iterator[tuple[str, bytes, int]]:
        """(device, payload, end offset) of each whole record of a segment."""
        data = path.read_bytes()
        offset = 0
        while offset + HEADER.size <= len(data):
            length, name_length = HEADER.unpack_from(data, offset)
            start = offset + HEADER.size
            end = start + name_length + length
            if length > MAX_RECORD or end > len(data):
                return
            try:
                device = data[start:start + name_length].decode("utf-8")
            except UnicodeDecodeError:
                return
            yield device, data[start + name_length:end], end
            offset = end
