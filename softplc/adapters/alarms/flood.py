"""Alarm floods (ISA-18.2): more alarms than an operator can handle, flagged as such.

ISA-18.2 (as EEMUA 191) calls it a flood when more than 10 alarms are annunciated to one
operator within 10 minutes, and the flood ends when fewer than 5 come within 10 minutes.
softplc has one operator position (every alarm reaches the same banner), so the rate counts
every alarm annunciated: an activation or re-alarm the operator is shown (not one that is
shelved, suppressed or out of service). The window slides on the runtime clock in steps of
`STEP` seconds, so its cost does not grow with the rate (a flood of 10,000 transitions a
second counts into 60 buckets).
"""

from __future__ import annotations

from collections import deque

FLOOD_ABOVE = 10  # more alarms than this within WINDOW: a flood
FLOOD_ENDS_BELOW = 5  # fewer than this within WINDOW: the flood is over
WINDOW = 600.0  # seconds
STEP = 10.0  # seconds per bucket of the sliding window


class FloodWatch:
    """Counts annunciated alarms in a sliding 10-minute window and says whether that is a flood."""

    def __init__(self) -> None:
        self._buckets: deque[list[int]] = deque()  # [step number, alarms in it], oldest first
        self.rate = 0  # alarms annunciated within the window
        self.flooding = False
        self.since: float | None = None  # wall-clock s the flood began (None: no flood)

    def annunciated(self, now: float) -> None:
        """One alarm shown to the operator at clock time `now`."""
        step = int(now // STEP)
        buckets = self._buckets
        if buckets and buckets[-1][0] == step:
            buckets[-1][1] += 1
        else:
            buckets.append([step, 1])
        self.rate += 1

    def update(self, now: float, wall: float) -> bool:
        """Forget what left the window; True when the flood began or ended (at clock time `now`, wall-clock `wall`)."""
        oldest = int(now // STEP) - int(WINDOW // STEP)
        buckets = self._buckets
        while buckets and buckets[0][0] <= oldest:
            self.rate -= buckets.popleft()[1]
        if not self.flooding and self.rate > FLOOD_ABOVE:
            self.flooding, self.since = True, wall
            return True
        if self.flooding and self.rate < FLOOD_ENDS_BELOW:
            self.flooding, self.since = False, None
            return True
        return False
