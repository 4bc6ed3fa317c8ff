"""Log lines about network peers that a flood cannot multiply.

A peer that opens a thousand connections, or tries a thousand passwords, must not write a
thousand lines: `PeerLog` writes the first line of a kind per peer at once, counts the others
for `interval` seconds, then writes one summary line ("… 999 more … in the last 10 s"); a
steady flood thus writes one line per peer and interval.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import Any

from softplc.util.plurals import counted

DEFAULT_INTERVAL = 10.0


def peer_host(peer_name: Any) -> str:
    """The address part of a socket peer name (('127.0.0.1', 53211) → '127.0.0.1')."""
    if isinstance(peer_name, (tuple, list)) and peer_name:
        return str(peer_name[0])
    return str(peer_name)


@dataclass
class _Quiet:
    """One (peer, kind) whose further lines are being counted instead of written."""

    count: int = 0
    details: dict[str, None] = field(default_factory=dict)  # a few distinct details, in order


class PeerLog:
    """At most one line per peer and kind of event per interval, plus one summary line."""

    MAX_DETAILS = 5

    def __init__(self, logger: logging.Logger, interval: float = DEFAULT_INTERVAL, *, service: str = "OPC UA") -> None:
        self.logger = logger
        self.interval = interval
        self.service = service  # names the server in the summary line
        self._quiet: dict[tuple[str, str], _Quiet] = {}

    def warning(self, peer: str, kind: str, message: str, *args: Any, detail: str | None = None) -> None:
        """Log `message % args` now, unless a line of this kind about `peer` was logged within the interval."""
        key = (peer, kind)
        quiet = self._quiet.get(key)
        if quiet is not None:
            quiet.count += 1
            if detail is not None and len(quiet.details) < self.MAX_DETAILS:
                quiet.details[detail] = None
            return
        self.logger.warning(message, *args)
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return  # no loop (a synchronous caller): nothing to summarise later, log every line
        self._quiet[key] = _Quiet()
        loop.call_later(self.interval, self._summarise, key)

    def _summarise(self, key: tuple[str, str]) -> None:
        quiet = self._quiet.get(key)
        if quiet is None:
            return
        if quiet.count == 0:
            del self._quiet[key]  # a quiet interval: the next event is logged at once again
            return
        peer, kind = key
        details = f" ({', '.join(quiet.details)})" if quiet.details else ""
        self.logger.warning("%s: %s from %s in the last %.0f s%s",
                            self.service, counted(quiet.count, f"more {kind}"), peer, self.interval, details)
        # Still flooding: stay quiet for another interval, so a steady flood writes one line per interval.
        self._quiet[key] = _Quiet()
        asyncio.get_running_loop().call_later(self.interval, self._summarise, key)
