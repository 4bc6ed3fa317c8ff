"""A one-line progress bar on stderr for scenario runs (only on a terminal, or when asked)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Redraws `[#####.....]  45 %  t=450 s  text` at most every `period` wall seconds."""

    def __init__(self, label: str, stream: TextIO | None = None, *, width: int = 30, period: float = 0.1) -> None:
        self.label = label
        self.stream = stream or sys.stderr
        self.width = width
        self.period = period
        self._last = 0.0
        self._shown = False

    def update(self, fraction: float, text: str = "", *, force: bool = False) -> None:
        now = time.monotonic()
        if not force and fraction < 1.0 and now - self._last < self.period:
            return
        self._last = now
        fraction = min(1.0, max(0.0, fraction))
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {100 * fraction:3.0f} %  {text}\033[K")
        self.stream.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
