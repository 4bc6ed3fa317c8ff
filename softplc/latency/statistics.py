"""Delay statistics as in thesis Table 8, plus percentiles and a fine histogram.

Mean and standard deviation follow the thesis's Equations 5.2 and 5.3 (sample standard
deviation, n − 1). The frequency categories are the thesis's: ≤ 20 ms, > 20 ms and ≤ 40 ms,
> 40 ms. Percentiles use linear interpolation between order statistics (numpy's default).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

PERCENTILES: tuple[float, ...] = (50.0, 95.0, 99.0, 99.9)


@dataclass(frozen=True)
class Histogram:
    """Counts of samples in bins [edges[i], edges[i+1]); the last bin also holds everything above."""

    width: float
    edges: list[float]
    counts: list[int]
    overflow_from: float | None = None  # set when the last bin collects the tail

    def rows(self) -> list[tuple[str, int]]:
        """(label, count) per bin, e.g. ('10–11', 5), the last '≥ 30' when it collects the tail."""
        labels = []
        for index, count in enumerate(self.counts):
            low, high = self.edges[index], self.edges[index + 1]
            if self.overflow_from is not None and index == len(self.counts) - 1:
                labels.append((f"≥ {_number(low)}", count))
            else:
                labels.append((f"{_number(low)}–{_number(high)}", count))
        return labels


@dataclass(frozen=True)
class DelayStatistics:
    """Summary of a set of delays in milliseconds (None where undefined, e.g. no samples)."""

    samples: int
    mean: float | None
    std: float | None
    mean_plus_std: float | None
    best: float | None
    worst: float | None
    share_le_20: float | None  # percent of samples ≤ 20 ms
    share_20_40: float | None  # percent > 20 ms and ≤ 40 ms
    share_gt_40: float | None  # percent > 40 ms
    count_le_20: int  # the samples behind each share
    count_20_40: int
    count_gt_40: int
    percentiles: dict[str, float] = field(default_factory=dict)  # "p50" → ms
    histogram: Histogram | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def summarize(delays_ms: Sequence[float], *, bin_width: float | None = None, max_bins: int = 60) -> DelayStatistics:
    """Table-8 statistics, percentiles and a histogram of `delays_ms` (NaNs are not allowed)."""
    values = np.asarray(list(delays_ms), dtype=np.float64)
    if values.size and not np.all(np.isfinite(values)):
        raise ValueError("delays must be finite numbers; count timeouts separately")
    n = int(values.size)
    if n == 0:
        return DelayStatistics(0, None, None, None, None, None, None, None, None, 0, 0, 0, {}, None)
    mean = float(values.mean())
    std = float(values.std(ddof=1)) if n > 1 else None
    counts = (
        int(np.count_nonzero(values <= 20.0)),
        int(np.count_nonzero((values > 20.0) & (values <= 40.0))),
        int(np.count_nonzero(values > 40.0)),
    )
    shares = tuple(100.0 * count / n for count in counts)
    percentiles = {_percentile_name(q): float(np.percentile(values, q)) for q in PERCENTILES}
    return DelayStatistics(
        samples=n,
        mean=mean,
        std=std,
        mean_plus_std=mean + std if std is not None else None,
        best=float(values.min()),
        worst=float(values.max()),
        share_le_20=shares[0],
        share_20_40=shares[1],
        share_gt_40=shares[2],
        count_le_20=counts[0],
        count_20_40=counts[1],
        count_gt_40=counts[2],
        percentiles=percentiles,
        histogram=histogram(values, bin_width, max_bins=max_bins),
    )


def histogram(values: Sequence[float] | np.ndarray, width: float | None = None, *, max_bins: int = 60) -> Histogram:
    """Bins of `width` ms from 0 (or a 1–2–5 width chosen for ≤ max_bins bins up to p99.9)."""
    data = np.asarray(values, dtype=np.float64)
    if data.size == 0:
        return Histogram(width or 1.0, [0.0, width or 1.0], [0])
    top = float(data.max())
    if width is None:
        width = nice_width(float(np.percentile(data, 99.9)), max_bins)
    low = math.floor(max(0.0, float(data.min())) / width) * width
    bins = max(1, math.floor((top - low) / width) + 1)
    overflow_from: float | None = None
    if bins > max_bins:
        bins = max_bins
        overflow_from = low + (bins - 1) * width
    edges = [low + index * width for index in range(bins + 1)]
    indices = np.floor((data - low) / width).astype(np.int64)
    indices = np.clip(indices, 0, bins - 1)
    counts = np.bincount(indices, minlength=bins)
    return Histogram(width, [round(edge, 9) for edge in edges], [int(c) for c in counts], overflow_from)


def nice_width(span: float, max_bins: int) -> float:
    """The smallest of 0.1, 0.2, 0.5, 1, 2, 5, 10, ... ms that covers `span` in ≤ max_bins bins."""
    if span <= 0:
        return 0.1
    exponent = math.floor(math.log10(span / max_bins)) if span / max_bins > 0 else -1
    for power in range(max(exponent, -1), exponent + 3):
        for mantissa in (1.0, 2.0, 5.0):
            width = mantissa * 10.0**power
            if span / width < max_bins:
                return round(width, 9)
    return round(10.0 ** (exponent + 3), 9)


def share_at_most(delays_ms: Sequence[float], limit: float) -> float | None:
    """Percent of samples ≤ `limit` (None when there are none)."""
    values = np.asarray(list(delays_ms), dtype=np.float64)
    if values.size == 0:
        return None
    return 100.0 * int(np.count_nonzero(values <= limit)) / int(values.size)


def _percentile_name(q: float) -> str:
    return "p" + (f"{q:g}".replace(".", ""))


def _number(value: float) -> str:
    return f"{value:g}"
