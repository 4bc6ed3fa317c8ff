"""Running timing statistics: min / max / mean over all samples, p99 over a recent window."""

from __future__ import annotations

import math
from typing import Any


class TimingSeries:
    """Samples of one timing quantity in seconds (e.g. a task's scan time)."""

    def __init__(self, window: int = 10_000) -> None:
        import numpy as np  # on first use: `softplc --help` imports this module (via config) and must start fast

        self._window = np.zeros(window, dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        self.count = 0
        self.total = 0.0
        self.min = math.inf
        self.max = 0.0
        self._filled = 0
        self._index = 0

    def add(self, value: float) -> None:
        self.count += 1
        self.total += value
        if value < self.min:
            self.min = value
        if value > self.max:
            self.max = value
        window = self._window
        window[self._index] = value
        self._index = (self._index + 1) % len(window)
        if self._filled < len(window):
            self._filled += 1

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else 0.0

    def percentile(self, q: float) -> float:
        """The q-th percentile (0–100) of the most recent samples (as np.percentile, linear)."""
        import numpy as np

        n = self._filled
        if not n:
            return 0.0
        if self.min == self.max:
            # Every sample since the reset alike (under a simulated clock scan and latency times
            # are all 0, a cycle always the interval): the window holds only that value. The
            # partition of 10,000 samples twice a second per series was 5 % of a simulated run.
            return self.min
        # np.percentile's own machinery costs ~10x the partition it needs; the runtime asks
        # for p99s twice a second per task, which dominated fast simulated runs.
        index = q / 100.0 * (n - 1)
        low = int(math.floor(index))
        high = min(low + 1, n - 1)
        part = np.partition(self._window[:n], (low, high))
        a, b, t = float(part[low]), float(part[high]), index - low
        difference = b - a
        return b - difference * (1.0 - t) if t >= 0.5 else a + difference * t  # numpy's _lerp

    def recent(self, count: int) -> Any:
        """The last `count` samples (at most the window's), oldest first, as a numpy array (a copy)."""
        import numpy as np

        count = max(0, min(count, self._filled))
        end = self._index
        if count <= end:
            return self._window[end - count:end].copy()
        return np.concatenate((self._window[len(self._window) - (count - end):], self._window[:end]))

    def summary(self) -> dict[str, float]:
        """min / max / mean / p99 in milliseconds."""
        if not self.count:
            return {"min": 0.0, "max": 0.0, "mean": 0.0, "p99": 0.0}
        return {
            "min": self.min * 1e3,
            "max": self.max * 1e3,
            "mean": self.mean * 1e3,
            "p99": self.percentile(99) * 1e3,
        }
