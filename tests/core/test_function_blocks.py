"""IEC 61131-3 function blocks on the simulated clock, scanned every 10 ms like a PLC task."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable

import pytest

from softplc import CTD, CTU, F_TRIG, R_TRIG, TOF, TON, TP, SimClock

INTERVAL = 0.01


async def scans(clock: SimClock, count: int) -> AsyncIterator[int]:
    """Yield k = 0..count-1 at simulated time k * 10 ms (absolute deadlines, like a task)."""
    for k in range(count):
        await clock.sleep_until(k * INTERVAL)
        yield k


async def run(count: int, body: Callable[[SimClock], Callable[[int], object]]) -> list[object]:
    """Scan `count` times; `body(clock)` returns the per-scan function; collect its results."""
    clock = SimClock()
    driver = asyncio.create_task(clock.drive())
    try:
        step = body(clock)
        return [step(k) async for k in scans(clock, count)]
    finally:
        driver.cancel()


def first(results: list[object], value: object = True) -> int:
    return results.index(value)


# -- TON ------------------------------------------------------------------------------------


@pytest.mark.parametrize("pt", [0.03, 0.1, 0.3, 0.7, 1.0, 2.0])
@pytest.mark.parametrize("start", [0, 3, 7, 13, 29, 58])
async def test_ton_q_rises_exactly_pt_after_in(pt: float, start: int) -> None:
    """Floating-point time must not delay Q by a scan: PT/interval scans after IN, exactly."""

    def body(clock: SimClock) -> Callable[[int], object]:
        timer = TON(clock)
        return lambda k: timer(IN=k >= start, PT=pt)

    results = await run(start + round(pt / INTERVAL) + 5, body)
    assert first(results) == start + round(pt / INTERVAL)
    assert all(results[first(results):])


async def test_ton_elapsed_time_reset_and_restart() -> None:
    def body(clock: SimClock) -> Callable[[int], object]:
        timer = TON(clock, PT=0.05)
        pattern = [True] * 3 + [False] + [True] * 8 + [False] * 2

        def step(k: int) -> tuple[bool, float]:
            timer(IN=pattern[k])
            return timer.Q, round(timer.ET, 6)

        return step

    results = await run(14, body)
    assert results[:4] == [(False, 0.0), (False, 0.01), (False, 0.02), (False, 0.0)]  # IN fell: reset
    # restarted at k=4 (t=40 ms): Q at k=9, ET capped at PT
    assert results[8] == (False, 0.04) and results[9] == (True, 0.05) and results[11] == (True, 0.05)
    assert results[12] == (False, 0.0)


async def test_ton_pt_zero_and_pt_change_while_timing() -> None:
    def body(clock: SimClock) -> Callable[[int], object]:
        zero = TON(clock, PT=0.0)
        changing = TON(clock)

        def step(k: int) -> tuple[bool, bool]:
            # PT shrinks from 1 s to 50 ms at k=3: Q as soon as 50 ms have elapsed since IN
            return zero(IN=True), changing(IN=True, PT=1.0 if k < 3 else 0.05)

        return step

    results = await run(8, body)
    assert [q for q, _ in results] == [True] * 8
    assert [q for _, q in results] == [False] * 5 + [True] * 3


# -- TOF ------------------------------------------------------------------------------------


async def test_tof_holds_q_for_pt_after_in_falls() -> None:
    def body(clock: SimClock) -> Callable[[int], object]:
        timer = TOF(clock, PT=0.3)
        # on 2..4 (falls at 5); on 40..41 (falls at 42); on again at 50, mid-delay (falls at 51)
        on = {2, 3, 4, 40, 41, 50}

        def step(k: int) -> tuple[bool, float]:
            timer(IN=k in on)
            return timer.Q, round(timer.ET, 6)

        return step

    results = await run(90, body)
    q = [r[0] for r in results]
    assert q[:2] == [False, False]  # never on yet: Q stays false
    assert q[2:35] == [True] * 33 and q[35] is False  # fell at 5: Q for 300 ms more
    assert results[20] == (True, 0.15)
    assert results[36] == (False, 0.3)  # ET stays at PT once expired
    assert q[40:81] == [True] * 41 and q[81] is False  # IN again at 50 restarted the delay


@pytest.mark.parametrize("fall", [1, 7, 33])
async def test_tof_drops_exactly_pt_after_fall(fall: int) -> None:
    def body(clock: SimClock) -> Callable[[int], object]:
        timer = TOF(clock, PT=0.7)
        return lambda k: timer(IN=k < fall)

    results = await run(fall + 80, body)
    assert results.index(False) == fall + 70


# -- TP -------------------------------------------------------------------------------------


async def test_tp_pulse_is_exactly_pt_and_not_retriggerable() -> None:
    def body(clock: SimClock) -> Callable[[int], object]:
        pulse = TP(clock, PT=0.1)
        # edge at 3 (held to 5); edge at 8 during the pulse (ignored); held from 30 to 50; edge at 60
        on = {3, 4, 5, 8} | set(range(30, 51)) | {60}

        def step(k: int) -> tuple[bool, float]:
            pulse(IN=k in on)
            return pulse.Q, round(pulse.ET, 6)

        return step

    results = await run(75, body)
    q = [r[0] for r in results]
    assert q[:3] == [False] * 3
    assert q[3:13] == [True] * 10 and q[13] is False  # exactly 100 ms, despite IN falling and the edge at 8
    assert q[30:40] == [True] * 10 and q[40:51] == [False] * 11
    assert results[45] == (False, 0.1)  # pulse over, IN still true: ET stays at PT
    assert results[51] == (False, 0.0)  # IN fell: ET resets
    assert q[60:70] == [True] * 10 and q[70] is False  # a one-scan IN gives a full pulse


# -- edge detectors and counters -------------------------------------------------------------


def test_r_trig_and_f_trig() -> None:
    signal = [False, True, True, False, True, False, False, True]
    rising, falling = R_TRIG(), F_TRIG()
    assert [rising(CLK=s) for s in signal] == [False, True, False, False, True, False, False, True]
    assert [falling(CLK=s) for s in signal] == [False, False, False, True, False, True, False, False]
    # a signal that is true at the first scan counts as a rising edge (IEC: the memory starts false)
    assert R_TRIG()(CLK=True) is True
    assert F_TRIG()(CLK=False) is False


def test_ctu_counts_edges_reset_wins() -> None:
    counter = CTU(PV=3)
    cu = [True, True, False, True, False, True, False, True]
    qs = [counter(CU=c) for c in cu]
    assert counter.CV == 4 and qs == [False, False, False, False, False, True, True, True]
    assert counter(CU=False, RESET=True) is False and counter.CV == 0
    assert counter(CU=True, RESET=True) is False and counter.CV == 0  # RESET wins over an edge
    assert counter(CU=False) is False
    assert counter(CU=True, PV=1) is True and counter.CV == 1


def test_ctd_load_and_count_down() -> None:
    counter = CTD(PV=2)
    assert counter.Q is True and counter.CV == 0
    assert counter(CD=False, LOAD=True) is False and counter.CV == 2
    assert counter(CD=True) is False and counter.CV == 1
    assert counter(CD=True) is False and counter.CV == 1  # held, not an edge
    assert counter(CD=False) is False
    assert counter(CD=True) is True and counter.CV == 0
    assert counter(CD=True, LOAD=True) is False and counter.CV == 2  # LOAD wins
