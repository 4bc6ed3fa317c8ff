"""The progress line of `softplc latency`: a bar with an ETA from the scenario's task durations.

On a terminal the line is redrawn at least once a second, whether or not the client reported a
handshake (in the slow scenario a handshake comes every 10–30 s). Elsewhere only start, end and
waiting lines are printed. Log records written to the same stream get a clean line first.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import TYPE_CHECKING, TextIO

from softplc.latency.plant import scenario_durations
from softplc.util.plurals import plural

if TYPE_CHECKING:
    from softplc.latency.results import Measurement
    from softplc.latency.target import Target

REDRAW_INTERVAL = 0.5  # s
CLEAR_LINE = "\r\033[K"


def remaining_seconds(durations: tuple[float, float, float], remaining: int, last_task: int | None,
                      since_last: float = 0.0, overhead: float = 0.0) -> float:
    """Time the next `remaining` handshakes take: each waits for the task the previous answer started.

    `last_task` is the TaskID of the last answer (None before the first, which starts task 1);
    `since_last` how long ago it was given; `overhead` the measured time per handshake beyond the
    task's duration (protocol, scans, the client's reads)."""
    if remaining <= 0:
        return 0.0
    first = (last_task or 1) - 1  # index of the task the next sample waits for
    cycles, rest = divmod(remaining, 3)
    total = cycles * sum(durations) + sum(durations[(first + j) % 3] for j in range(rest))
    if last_task is not None:
        total -= min(since_last, durations[first])
    return max(0.0, total + remaining * overhead)


def overhead_per_handshake(durations: tuple[float, float, float], answers: list[tuple[float, int]]) -> float:
    """Mean time per handshake beyond its task's duration, from (answer time, TaskID) in order."""
    if len(answers) < 2:
        return 0.0
    tasks = sum(durations[task - 1] for _, task in answers[:-1] if task in (1, 2, 3))
    return max(0.0, (answers[-1][0] - answers[0][0] - tasks) / (len(answers) - 1))


def estimate_seconds(target: Target) -> float:
    """How long a run takes before it has started: its tasks, plus a few seconds to start."""
    if target.duration is not None:
        return target.duration
    return remaining_seconds(scenario_durations(target.scenario), target.samples or 0, None) + 3.0


def summary(run: Measurement) -> str:
    """What was requested, measured, missed and not attempted, and why the run ended."""
    target = run.target
    measured = len(run.ok_samples)
    if not run.connected and not run.samples:
        return "not measured — " + ("; ".join(run.errors) or run.ended or "the client never connected")
    if target.duration is not None:
        text = f"{plural(measured, 'sample')} in {run.wall_seconds:.0f} of {target.duration:g} s requested"
    elif run.complete and measured == target.samples:
        text = f"{plural(measured, 'sample')} in {run.wall_seconds:.0f} s"
    else:
        text = f"samples {measured} of {target.samples} requested, in {run.wall_seconds:.0f} s"
    if run.missed:
        text += f"; missed {run.missed}"
        if run.missed_notes:
            text += " (" + "; ".join(run.missed_notes) + ")"
    if run.not_attempted:
        text += f"; not attempted {run.not_attempted}"
    if run.complete:
        return text + " — done"
    return text + f" — INCOMPLETE, run ended: {run.ended or 'error'}" + "".join(f"; {error}" for error in _new(run.errors, run.ended))


def _new(errors: list[str], ended: str) -> list[str]:
    return [error for error in errors if error != ended]


class ProgressBar:
    """A one-line progress bar with ETA on stderr (only on a terminal; otherwise start and end lines)."""

    def __init__(self, target: Target, stream: TextIO) -> None:
        self.target = target
        self.stream = stream
        self.live = stream.isatty()
        self.durations = scenario_durations(target.scenario)
        self.run: Measurement | None = None
        self.announced = False
        self.activity = ""
        self.connected_at: float | None = None
        self.answers: list[tuple[float, int]] = []  # (t_done, TaskID) of every answer, warm-up first
        self.drawn = False
        self._clearer = _ClearLineFilter(self)

    def update(self, run: Measurement) -> None:
        """Called by the measurement at each report of the client."""
        self.run = run
        if run.connected and not self.announced:
            self.announced = True
            self.connected_at = time.monotonic()
            self._line(f"{self.target.label}: client process {run.client_pid} measuring {run.endpoint}")
        answers = [*run.warmup[:1], *run.samples]
        for sample in answers[len(self.answers):]:
            self.answers.append((sample.t_done, sample.task_id))
        if run.activity != self.activity:
            self.activity = run.activity
            if run.activity:
                self._line(run.activity)
        self.draw()

    def eta(self, now: float) -> float:
        target, run = self.target, self.run
        if target.duration is not None:
            elapsed = now - self.connected_at if self.connected_at is not None else 0.0
            return max(0.0, target.duration - elapsed)
        done = len(run.samples) if run is not None else 0
        remaining = (target.samples or 0) - done
        if not self.answers:
            return remaining_seconds(self.durations, remaining, None)
        last_done, last_task = self.answers[-1]
        overhead = overhead_per_handshake(self.durations, self.answers)
        return remaining_seconds(self.durations, remaining, last_task, now - last_done, overhead)

    def draw(self, now: float | None = None) -> None:
        """Redraw the line (on a terminal)."""
        if not self.live:
            return
        now = time.monotonic() if now is None else now
        target, run = self.target, self.run
        done = len(run.samples) if run is not None else 0
        if target.duration is not None:
            elapsed = now - self.connected_at if self.connected_at is not None else 0.0
            fraction = min(1.0, elapsed / target.duration)
            count = plural(done, "sample")
        else:
            fraction = min(1.0, done / (target.samples or 1))
            count = f"{done}/{target.samples} samples"
        width = 28
        filled = int(width * fraction)
        state = ""
        if run is None or not run.connected:
            state = "  starting"
        elif self.activity:
            state = "  waiting for the PLC's next Ready (Ctrl-C skips)"
        figures = ""
        last = run.samples[-1] if run is not None and run.samples else None
        if last is not None and last.plc_delay_ms is not None:
            figures = f"  last: PLC {last.plc_delay_ms:.0f} ms"
            hires = last.hires_ms(run.same_clock) if run is not None else None
            if hires is not None:
                figures += f", hi-res {hires:.2f} ms"
        trouble = f"  missed {run.missed} timeouts {run.timeouts}" if run is not None and (run.missed or run.timeouts) else ""
        line = f"{target.label:14s} [{'#' * filled}{'.' * (width - filled)}] {count}  ETA {clock_text(self.eta(now))}{state}{figures}{trouble}"
        print(CLEAR_LINE + line, end="", file=self.stream, flush=True)
        self.drawn = True

    async def redraw(self, interval: float = REDRAW_INTERVAL) -> None:
        """Redraw every `interval` seconds until cancelled; log records meanwhile get a clean line."""
        self._clearer.install()
        try:
            while True:
                self.draw()
                await asyncio.sleep(interval)
        finally:
            self._clearer.remove()

    def clear(self) -> None:
        """Leave the line empty (before something else is printed on the stream)."""
        if self.drawn:
            print(CLEAR_LINE, end="", file=self.stream, flush=True)
            self.drawn = False

    def finish(self, run: Measurement) -> None:
        self.clear()
        self._line(f"{self.target.label}: {summary(run)}")

    def _line(self, text: str) -> None:
        self.clear()
        print(text, file=self.stream, flush=True)


class _ClearLineFilter(logging.Filter):
    """Clears the progress line before a log handler writes to the same stream."""

    def __init__(self, bar: ProgressBar) -> None:
        super().__init__()
        self.bar = bar
        self.handlers: list[logging.Handler] = []

    def filter(self, record: logging.LogRecord) -> bool:
        self.bar.clear()
        return True

    def install(self) -> None:
        if not self.bar.live:
            return
        for handler in logging.getLogger().handlers:
            if getattr(handler, "stream", None) is self.bar.stream:
                handler.addFilter(self)
                self.handlers.append(handler)

    def remove(self) -> None:
        for handler in self.handlers:
            handler.removeFilter(self)
        self.handlers.clear()


def clock_text(seconds: float) -> str:
    seconds = max(0, int(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    return f"{seconds // 60}m{seconds % 60:02d}s"
