"""IEC 61131-3 standard function blocks: TON, TOF, TP, R_TRIG, F_TRIG, CTU, CTD.

Timers take their time from the runtime clock, so they behave identically on the simulated
clock. Call a block once per scan, as in a PLC:

    self.delay = TON(self.clock)          # in setup()
    self.delay(IN=self.ready, PT=2.0)     # in scan(); PT in seconds
    if self.delay.Q: ...

**Restarts make no false edges.** IEC 61131-3 starts an edge detector's memory at FALSE, so at a
cold start an input that is already TRUE is a rising edge in the first scan — kept here for the
plant's start. A program that is *restarted* (after a fault, by `reset_faults`, by
`programs.start`/`restart`, or as the new version of an online change) runs its `setup()` inside
`warm_start()`: every edge detector created there (R_TRIG, F_TRIG, and those inside CTU, CTD
and TP) takes the value of its first call as its memory instead, so a signal that stayed high
across the fault is not counted again. Timers (TON, TOF) simply start from their current input.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

from softplc.core.clock import Clock

# The IEC names are kept on purpose (TON, IN, PT, Q, ET, CU, PV, CV): PLC engineers know them.
# ruff: noqa: N802, N803, N815

# Clock times are sums of floats (origin + k * interval), so "PT has elapsed" is decided with a
# tolerance; otherwise 8.0 - 6.000000000000001 < 2.0 would delay Q by a whole scan. 1 µs is far
# below the shortest task interval (100 µs) and far above float rounding over months of runtime.
_TOLERANCE = 1e-6

_WARM_START: contextvars.ContextVar[bool] = contextvars.ContextVar("softplc_warm_start", default=False)


@contextlib.contextmanager
def warm_start() -> Iterator[None]:
    """Edge detectors created inside take their first input as memory (a restart's `setup()`)."""
    token = _WARM_START.set(True)
    try:
        yield
    finally:
        _WARM_START.reset(token)


def _learns_first_input() -> bool:
    """Whether a block created now is created by a warm start (see `warm_start`)."""
    return _WARM_START.get()


class TON:
    """On-delay timer: Q becomes true PT seconds after IN became true; ET is elapsed time."""

    def __init__(self, clock: Clock, PT: float = 0.0) -> None:
        self._clock = clock
        self.PT = PT
        self.IN = False
        self.Q = False
        self.ET = 0.0
        self._start: float | None = None

    def __call__(self, IN: bool, PT: float | None = None) -> bool:
        if PT is not None:
            self.PT = PT
        self.IN = IN
        if not IN:
            self._start = None
            self.Q = False
            self.ET = 0.0
            return self.Q
        now = self._clock.now()
        if self._start is None:
            self._start = now
        elapsed = now - self._start
        self.Q = elapsed >= self.PT - _TOLERANCE
        self.ET = self.PT if self.Q else elapsed
        return self.Q


class TOF:
    """Off-delay timer: Q follows IN up, and drops PT seconds after IN went false."""

    def __init__(self, clock: Clock, PT: float = 0.0) -> None:
        self._clock = clock
        self.PT = PT
        self.IN = False
        self.Q = False
        self.ET = 0.0
        self._fall: float | None = None

    def __call__(self, IN: bool, PT: float | None = None) -> bool:
        if PT is not None:
            self.PT = PT
        self.IN = IN
        if IN:
            self._fall = None
            self.Q = True
            self.ET = 0.0
            return self.Q
        if not self.Q:
            return self.Q
        now = self._clock.now()
        if self._fall is None:
            self._fall = now
        elapsed = now - self._fall
        self.ET = min(elapsed, self.PT)
        if elapsed >= self.PT - _TOLERANCE:
            self.Q = False
            self.ET = self.PT
        return self.Q


class TP:
    """Pulse timer: a rising edge of IN gives a pulse of exactly PT seconds on Q."""

    def __init__(self, clock: Clock, PT: float = 0.0) -> None:
        self._clock = clock
        self.PT = PT
        self.IN = False
        self.Q = False
        self.ET = 0.0
        self._start: float | None = None
        self._previous_in = False
        self._learn = _learns_first_input()

    def __call__(self, IN: bool, PT: float | None = None) -> bool:
        if PT is not None:
            self.PT = PT
        if self._learn:  # created by a warm start: an IN already high is no edge
            self._learn = False
            self._previous_in = IN
        now = self._clock.now()
        if IN and not self._previous_in and self._start is None:
            self._start = now
        self._previous_in = IN
        self.IN = IN
        if self._start is not None:
            elapsed = now - self._start
            if elapsed < self.PT - _TOLERANCE:
                self.Q = True
                self.ET = elapsed
            else:
                self.Q = False
                self.ET = self.PT
                if not IN:  # the pulse is over and IN fell: ready for the next edge
                    self._start = None
                    self.ET = 0.0
        else:
            self.Q = False
            self.ET = 0.0
        return self.Q


class R_TRIG:
    """Rising-edge detector: Q is true for the one scan in which CLK goes false → true."""

    def __init__(self) -> None:
        self.CLK = False
        self.Q = False
        self._learn = _learns_first_input()

    def __call__(self, CLK: bool) -> bool:
        if self._learn:  # created by a warm start: the first CLK is the memory, not an edge
            self._learn = False
            self.CLK = CLK
        self.Q = CLK and not self.CLK
        self.CLK = CLK
        return self.Q


class F_TRIG:
    """Falling-edge detector: Q is true for the one scan in which CLK goes true → false."""

    def __init__(self) -> None:
        self.CLK = False
        self.Q = False
        self._learn = _learns_first_input()

    def __call__(self, CLK: bool) -> bool:
        if self._learn:  # created by a warm start: the first CLK is the memory, not an edge
            self._learn = False
            self.CLK = CLK
        self.Q = self.CLK and not CLK
        self.CLK = CLK
        return self.Q


class CTU:
    """Up counter: CV counts rising edges of CU; Q when CV ≥ PV; RESET sets CV to 0."""

    def __init__(self, PV: int = 0) -> None:
        self.PV = PV
        self.CV = 0
        self.Q = False
        self._edge = R_TRIG()

    def __call__(self, CU: bool, RESET: bool = False, PV: int | None = None) -> bool:
        if PV is not None:
            self.PV = PV
        rising = self._edge(CU)
        if RESET:
            self.CV = 0
        elif rising:
            self.CV += 1
        self.Q = self.CV >= self.PV
        return self.Q


class CTD:
    """Down counter: CV counts down on rising edges of CD; Q when CV ≤ 0; LOAD sets CV = PV."""

    def __init__(self, PV: int = 0) -> None:
        self.PV = PV
        self.CV = 0
        self.Q = True
        self._edge = R_TRIG()

    def __call__(self, CD: bool, LOAD: bool = False, PV: int | None = None) -> bool:
        if PV is not None:
            self.PV = PV
        rising = self._edge(CD)
        if LOAD:
            self.CV = self.PV
        elif rising:
            self.CV -= 1
        self.Q = self.CV <= 0
        return self.Q
