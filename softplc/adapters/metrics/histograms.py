"""Prometheus histograms of a task's timings, made at scrape time from what the scan keeps anyway.

The scan records each cycle's scan time, cycle time and start latency in a `TimingSeries` (a
window of the last 10,000 samples, plus count and total). A scrape bins the samples added since
the previous scrape into the buckets and adds them to running totals — no work in the scan, and
a histogram whose `_count` and `_sum` are exact. Two rare cases, both documented:

- more samples than the window holds arrived since the last scrape (a 10 ms task scraped less
  often than every 100 s): the window's distribution stands for the whole gap (`_count` and
  `_sum` stay exact, the buckets are scaled to them);
- the statistics were reset (`_sys.reset_stats`): the running totals go on (Prometheus counters
  never go down); the samples between the last scrape and the reset are not in the buckets.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from softplc.core.stats import TimingSeries

# Seconds: a scan of a soft PLC takes 10 µs .. 100 ms; a stall is counted in +Inf.
SCAN_BUCKETS = (0.00005, 0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0)
# Start latency (release → start) of a healthy task is well under a millisecond.
LATENCY_BUCKETS = (0.00005, 0.0001, 0.00025, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0)
# Cycle time (start → next start) in multiples of the task's interval: jitter shows around 1,
# a skipped release at 2 and more.
CYCLE_FACTORS = (0.5, 0.9, 0.95, 0.99, 1.01, 1.05, 1.1, 1.5, 2.0, 3.0, 5.0)


def cycle_buckets(interval: float) -> tuple[float, ...]:
    """The cycle-time buckets of a task with this interval (s)."""
    return tuple(round(interval * factor, 9) for factor in CYCLE_FACTORS)


class SeriesHistogram:
    """A cumulative histogram fed from one TimingSeries at each scrape."""

    def __init__(self, bounds: Sequence[float]) -> None:
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.counts = np.zeros(len(bounds) + 1, dtype=np.int64)  # per bucket (not cumulative); the last is +Inf
        self.count = 0
        self.sum = 0.0
        self._seen = 0  # series.count at the last scrape
        self._seen_total = 0.0
        self._resets = 0

    def update(self, series: TimingSeries, resets: int) -> None:
        """Add the samples the series got since the last update (`resets`: its owner's reset count)."""
        if resets != self._resets:  # reset since: its count and total start again from 0
            self._resets, self._seen, self._seen_total = resets, 0, 0.0
        new = series.count - self._seen
        if new <= 0:
            return
        samples = series.recent(new)
        counts = np.bincount(np.searchsorted(self.bounds, samples, side="left"), minlength=len(self.counts))
        if len(samples) < new:  # more arrived than the window holds: scale its distribution to all of them
            scaled = np.floor(counts * (new / len(samples))).astype(np.int64)
            scaled[int(np.argmax(counts))] += new - int(scaled.sum())
            counts = scaled
        self.counts += counts
        self.count += new
        self.sum += series.total - self._seen_total
        self._seen, self._seen_total = series.count, series.total

    def buckets(self) -> list[tuple[str, float]]:
        """Cumulative (le, count) pairs as prometheus_client's HistogramMetricFamily takes them."""
        cumulative = np.cumsum(self.counts)
        pairs: list[tuple[str, float]] = [(_le(bound), float(total)) for bound, total in zip(self.bounds, cumulative[:-1])]
        pairs.append(("+Inf", float(self.count)))
        return pairs


def _le(bound: Any) -> str:
    return repr(float(bound))
