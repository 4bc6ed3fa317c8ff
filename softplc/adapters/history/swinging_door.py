"""Swinging-door compression (OSIsoft PI's CompDev / CompMin / CompMax) for one tag.

The last archived point A is the hinge of two doors, `deviation` above and below it. Each new
value narrows the opening: the upper door's slope is the smallest slope from A to (t, v +
deviation) seen so far, the lower door's the largest slope to (t, v - deviation). While the
doors are open (lower ≤ upper), one straight line from A passes within `deviation` of every
value since A, so nothing needs storing; the latest value is *held*. When a value closes the
doors, the held value is archived and becomes the new hinge. Every value since the hinge lies
within `deviation` of one line through the doors, and the line from the hinge to the archived
point departs from that one by less than `deviation`: reading the archive back with linear
interpolation stays within twice the deviation of every value (on average within it).

`min_interval`: no two archived points closer than this (a door closing sooner just restarts).
`max_interval`: the held value is archived once this long has passed since the last archived
point, so a slow drift still reaches the archive (a heartbeat; see `due`).
"""

from __future__ import annotations

import math

Point = tuple[float, float]


class SwingingDoor:
    """Decides which of a tag's values to archive (pure: no I/O, no clock)."""

    __slots__ = ("deviation", "min_interval", "max_interval", "archived", "held", "_upper", "_lower")

    def __init__(self, deviation: float, min_interval: float = 0.0, max_interval: float = math.inf) -> None:
        if deviation < 0:
            raise ValueError("the compression deviation cannot be negative")
        self.deviation = deviation
        self.min_interval = min_interval
        self.max_interval = max_interval
        self.archived: Point | None = None  # the hinge: the last archived point
        self.held: Point | None = None  # the latest value, not archived yet
        self._upper = math.inf
        self._lower = -math.inf

    def offer(self, when: float, value: float) -> list[Point]:
        """A new value; returns the points to archive now (none, the held one, or this one)."""
        archived = self.archived
        if archived is None:
            return self._archive((when, value))
        elapsed = when - archived[0]
        if elapsed <= 0:  # same instant as the hinge: the newer value replaces the held one
            self.held = (when, value)
            return []
        upper = min(self._upper, (value + self.deviation - archived[1]) / elapsed)
        lower = max(self._lower, (value - self.deviation - archived[1]) / elapsed)
        result: list[Point] = []
        if lower > upper and self.held is not None:
            held = self.held
            if held[0] - archived[0] >= self.min_interval:
                result = self._archive(held)
                archived = held
                elapsed = when - archived[0]
                upper = (value + self.deviation - archived[1]) / elapsed if elapsed > 0 else math.inf
                lower = (value - self.deviation - archived[1]) / elapsed if elapsed > 0 else -math.inf
            else:
                # Too soon after the last archived point: restart the doors from this value.
                upper = (value + self.deviation - archived[1]) / elapsed
                lower = (value - self.deviation - archived[1]) / elapsed
        self._upper, self._lower = upper, lower
        self.held = (when, value)
        if when - archived[0] >= self.max_interval:
            result += self._archive(self.held)
        return result

    def due(self, now: float) -> bool:
        """Whether the heartbeat is due: `max_interval` has passed since the last archived point."""
        return self.archived is not None and now - self.archived[0] >= self.max_interval

    def release(self) -> list[Point]:
        """Archive the held value now (a heartbeat, a quality change, the end of recording)."""
        if self.held is None:
            return []
        return self._archive(self.held)

    def restart(self) -> None:
        """Forget everything: the next value is archived as it comes (after a gap or a bad value)."""
        self.archived = None
        self.held = None
        self._upper, self._lower = math.inf, -math.inf

    def _archive(self, point: Point) -> list[Point]:
        self.archived = point
        self.held = None
        self._upper, self._lower = math.inf, -math.inf
        return [point]
