"""The progress line of `softplc latency`: ETA from the task durations, redrawn without events, clean log lines."""

from __future__ import annotations

import asyncio
import io
import logging

import pytest

from softplc.latency.measurement import Measurement, Sample, Target
from softplc.latency.progress import (
    CLEAR_LINE,
    ProgressBar,
    overhead_per_handshake,
    plural,
    remaining_seconds,
    summary,
)

SLOW = (10.0, 20.0, 30.0)


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


async def until(condition, timeout: float = 5.0) -> None:  # type: ignore[no-untyped-def]
    """Wait until `condition()` holds (checked every 10 ms), or fail after `timeout` seconds."""

    async def poll() -> None:
        while not condition():
            await asyncio.sleep(0.01)

    await asyncio.wait_for(poll(), timeout)


def answer(index: int, task_id: int, t_done: float) -> Sample:
    return Sample(index, task_id, "ok" if index else "start", t_done - 0.005, t_done - 0.002, t_done - 0.001, t_done,
                  10.0, 1, index)


def test_remaining_time_by_hand():
    # 100 samples before the warm-up: it starts task 1, so the samples wait for tasks 1, 2, 3, 1, ...
    # 33 whole cycles (60 s each) and one more task 1: 1990 s.
    assert remaining_seconds(SLOW, 100, None) == pytest.approx(1990.0)
    # The warm-up gave task 1 four seconds ago: 6 s of it are left.
    assert remaining_seconds(SLOW, 100, 1, since_last=4.0) == pytest.approx(1986.0)
    # 99 to go after an answer that started task 2 five seconds ago, 50 ms overhead each.
    assert remaining_seconds(SLOW, 99, 2, since_last=5.0, overhead=0.05) == pytest.approx(1980.0 - 5.0 + 99 * 0.05)
    # Two to go after task 3 was given: tasks 3 and 1.
    assert remaining_seconds(SLOW, 2, 3) == pytest.approx(40.0)
    assert remaining_seconds(SLOW, 0, 3) == 0.0


def test_overhead_is_the_time_beyond_the_tasks():
    # Answers giving tasks 1, 2, 3 at 0, 10.02, 30.04: tasks 1 and 2 took 30 s of the 30.04 s.
    assert overhead_per_handshake(SLOW, [(0.0, 1), (10.02, 2), (30.04, 3)]) == pytest.approx(0.02)
    assert overhead_per_handshake(SLOW, [(0.0, 1)]) == 0.0


def test_eta_counts_down_with_the_clock_in_the_slow_scenario():
    """The audit saw 10m03s → 4m57s → 7m04s while ~9.5 min remained: the ETA must follow the tasks."""
    target = Target("modbus", "slow", samples=9)
    run = Measurement(target, connected=True)
    bar = ProgressBar(target, io.StringIO())
    overhead = 0.03
    # The true timeline: warm-up at 0 gives task 1; each sample comes its task's time + overhead later.
    times, task, t = [], 1, 0.0
    for index in range(10):
        times.append((index, task, t))
        t += SLOW[task - 1] + overhead
        task = task % 3 + 1
    end = times[-1][2]
    run.warmup.append(answer(0, 1, 0.0))
    bar.update(run)
    for index, task_id, at in times[1:]:
        # Between reports the ETA is the true time left (±1 s: the overhead is not known yet at first).
        for now in (at - 9.0, at - 1.0):
            if now > 0:
                assert bar.eta(now) == pytest.approx(end - now, abs=1.0), (index, now)
        run.samples.append(answer(index, task_id, at))
        bar.update(run)
    assert bar.eta(end) == 0.0


async def test_the_line_is_redrawn_without_any_report():
    stream = Terminal()
    bar = ProgressBar(Target("opcua", "slow", samples=100), stream)
    redraw = asyncio.create_task(bar.redraw(interval=0.01))
    try:
        await until(lambda: stream.getvalue().count(CLEAR_LINE) >= 3)
    finally:
        redraw.cancel()
    assert "0/100 samples" in stream.getvalue() and "ETA 33m10s" in stream.getvalue()


async def test_a_log_record_gets_a_clean_line():
    stream = Terminal()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(logging.Formatter("%(message)s"))
    logging.getLogger().addHandler(handler)
    bar = ProgressBar(Target("modbus", "fast", samples=10), stream)
    redraw = asyncio.create_task(bar.redraw(interval=0.01))
    try:
        await until(lambda: bar.drawn)
        logging.getLogger("softplc.adapters.modbus").warning("Modbus client misbehaved (ignored): Cancel send")
    finally:
        redraw.cancel()
        await asyncio.gather(redraw, return_exceptions=True)
        logging.getLogger().removeHandler(handler)
    text = stream.getvalue()
    before = text[:text.index("Modbus client misbehaved")]
    assert before.endswith(CLEAR_LINE)
    assert not handler.filters  # removed with the bar


def test_what_the_run_waits_for_is_said_on_its_own_line():
    stream = io.StringIO()  # not a terminal: no bar, but this line still shows
    target = Target("modbus", "slow", samples=10)
    bar = ProgressBar(target, stream)
    run = Measurement(target, connected=True, client_pid=4242, endpoint="127.0.0.1:502")
    bar.update(run)
    run.activity = "modbus slow: the client is gone; waiting up to 31 s for its next Ready (Ctrl-C skips this)"
    bar.update(run)
    lines = stream.getvalue().splitlines()
    assert lines == ["modbus slow: client process 4242 measuring 127.0.0.1:502", run.activity]


def test_summary_says_requested_measured_missed_and_not_attempted():
    target = Target("modbus", "slow", samples=100)
    run = Measurement(target, connected=True, client_exit=-9, ended="client died", missed=1,
                      errors=["the client process was killed by signal 9"],
                      missed_notes=["a Ready the PLC set 16.0 s after the client ended, never answered"])
    run.samples = [answer(index, index % 3 + 1, float(index)) for index in range(1, 13)]
    text = summary(run)
    assert text.startswith("samples 12 of 100 requested")
    assert "missed 1 (a Ready the PLC set 16.0 s after the client ended, never answered)" in text
    assert "not attempted 87" in text
    assert "run ended: client died; the client process was killed by signal 9" in text
    assert run.not_attempted == 87


def test_plurals():
    assert plural(1, "sample") == "1 sample" and plural(0, "sample") == "0 samples" and plural(2, "run") == "2 runs"
    target = Target("modbus", "fast", samples=1)
    run = Measurement(target, connected=True, client_exit=0, ended="complete", wall_seconds=1.0)
    run.samples = [answer(1, 2, 1.0)]
    assert summary(run) == "1 sample in 1 s — done"
