"""How old the live channel's values are when they go on the wire: the server's half of change → screen.

Each frame of changes a client is sent is recorded with the age of its oldest value: the time
from the change's commit in the tag database (its timestamp) to the frame's last byte handed to
the client's socket. `GET /api/diagnostics?since=T` gives percentiles of the frames sent since
T (`time.monotonic()`, one clock for every process of the machine), so a benchmark can tell
the server's part from the browser's. Only on the real clock: simulated timestamps say nothing
about real time.
"""

from __future__ import annotations

import time
from collections import deque
from typing import Any

KEPT = 200_000  # frames remembered (20 s of ten clients at 100 frames a second, and more)


class DeliveryRecord:
    """Ages (s) of the frames sent, with the real time each went out."""

    def __init__(self) -> None:
        self._samples: deque[tuple[float, float]] = deque(maxlen=KEPT)

    def add(self, age: float) -> None:
        self._samples.append((time.monotonic(), age))

    def summary(self, since: float = 0.0) -> dict[str, Any]:
        """Percentiles (ms) of the ages of the frames sent since `since` (monotonic seconds)."""
        ages = sorted(age for at, age in self._samples if at >= since)
        if not ages:
            return {"frames": 0}

        def at(fraction: float) -> float:
            return round(ages[min(len(ages) - 1, int(fraction * len(ages)))] * 1e3, 2)

        return {"frames": len(ages), "p50_ms": at(0.50), "p95_ms": at(0.95), "p99_ms": at(0.99), "max_ms": round(ages[-1] * 1e3, 2)}
