"""Running timing statistics: min / max / mean over all samples, p99 over a recent window."""

from __future__ import annotations

import math

import numpy as np


class TimingSeries:
    """Samples of one timing quantity in seconds (e.g. a task's scan time)."""

    def __init__(self, window: int = 10_000) -> None:
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
        """The q-th percentile (0–100) of the most recent samples."""
        if not self._filled:
            return 0.0
        return float(np.percentile(self._window[: self._filled], q))

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
