"""The two counters of an edge node: `seq` per message and `bdSeq` per MQTT session (specification §5.7, §6.4.1).

`seq` is 0 in every NBIRTH and one more in each following NBIRTH, DBIRTH, NDATA, DDATA and
DDEATH of the node, wrapping from 255 to 0; NDEATH and commands carry none.

`bdSeq` ("birth/death sequence") is in the NDEATH registered as the last will of each MQTT
CONNECT and in the NBIRTHs of that session, so a host can tell which birth a death ends. It
starts at 0 and goes up by one per CONNECT, wrapping from 255 to 0. It is kept in a file, so a
runtime that was killed and started again goes on from the next number: a late last will of the
old process can then never be taken for the death of the new session.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

log = logging.getLogger(__name__)

WRAP = 256


class MessageSequence:
    """`seq`: 0 at a birth, +1 per message, 255 → 0."""

    def __init__(self) -> None:
        self.value = 0

    def birth(self) -> int:
        self.value = 0
        return 0

    def next(self) -> int:
        self.value = (self.value + 1) % WRAP
        return self.value


class BirthDeathSequence:
    """`bdSeq`, kept in `path`: the number of the current (or next) MQTT session.

    `for_connect(connects)` is asked for the will of each CONNECT, with the number of sessions
    the connection has opened so far: when the previous attempt never reached the broker (the
    count did not change), its number was never registered and is used again; otherwise the next
    number is taken and written down before the CONNECT goes out.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        stored = self._read()
        self.value = 0 if stored is None else (stored + 1) % WRAP
        self._taken = False  # whether `value` was handed to a CONNECT yet
        self._connects_seen = -1

    def for_connect(self, connects: int) -> int:
        """The bdSeq of the CONNECT about to be sent."""
        if self._taken and connects != self._connects_seen:
            self.value = (self.value + 1) % WRAP
        self._taken = True
        self._connects_seen = connects
        self._write(self.value)
        return self.value

    def follow(self, value: int) -> None:
        """`value` is the bdSeq of the other member of a redundant pair (the active): this one's next session takes the number after it."""
        self.value = (value + 1) % WRAP
        self._taken = False
        self._write(value)

    def _read(self) -> int | None:
        try:
            text = self.path.read_text(encoding="ascii").strip()
        except FileNotFoundError:
            return None
        except OSError as error:
            log.warning("Sparkplug: cannot read the last bdSeq from %s (%s); starting at 0", self.path, error)
            return None
        if not text.isdigit() or int(text) >= WRAP:
            log.warning("Sparkplug: %s holds %r, not a bdSeq (0..255); starting at 0", self.path, text[:20])
            return None
        return int(text)

    def _write(self, value: int) -> None:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            partial = self.path.with_suffix(".partial")
            partial.write_text(f"{value}\n", encoding="ascii")
            os.replace(partial, self.path)  # never a half-written number after a crash
        except OSError as error:
            log.warning("Sparkplug: cannot keep the bdSeq in %s (%s): a restarted runtime may reuse it", self.path, error)
