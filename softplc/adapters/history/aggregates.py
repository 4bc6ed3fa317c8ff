"""Pure functions over samples: the OPC UA Part 13 aggregates per interval, and plot decimation.

A tag's history is either *sloped* (a float: the value moves linearly between two stored
samples, as swinging-door compression assumes) or *stepped* (integers, booleans, strings: a value
holds until the next sample). Results carry a quality and Part 13's flags (calculated,
interpolated, partial, multi-value, no data...), so an OPC UA server can give each value its exact
StatusCode; `AggregateConfig` is Part 13's AggregateConfiguration. Bounding values (the value at
an instant between samples) are in `bounds.py`.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from softplc.core.tags import Quality


class Sample(NamedTuple):
    """One stored value of a tag."""

    time: float  # Unix seconds (simulated seconds for a --sim store)
    value: Any
    quality: Quality = Quality.GOOD


class Flags(enum.IntFlag):
    """What a processed or interpolated value is (Part 13 §5.3.3; the first five are its bit values)."""

    NONE = 0  # a raw, stored value
    CALCULATED = 0x1  # computed from several values
    INTERPOLATED = 0x2  # estimated between (or extrapolated after) stored values
    PARTIAL = 0x4  # the interval is shorter than the processing interval
    MULTI_VALUE = 0x10  # the minimum or maximum occurs more than once
    NO_DATA = 0x100  # quality BAD: there is no data to compute from (OPC UA Bad_NoData)
    SUB_NORMAL = 0x200  # quality UNCERTAIN: less good data than asked for (Uncertain_DataSubNormal)
    NO_BOUND = 0x400  # a bounding value that was not found (OPC UA Bad_BoundNotFound)


class Result(NamedTuple):
    """A value computed or read for a time: a `Sample` plus its `Flags`."""

    time: float
    value: Any
    quality: Quality = Quality.GOOD
    flags: Flags = Flags.NONE


class Aggregate(enum.Enum):
    """The processed reads offered (OPC UA Part 13 names and semantics)."""

    INTERPOLATIVE = "interpolative"  # the value at the interval's start (interpolated bounding value)
    AVERAGE = "average"  # the arithmetic mean of the interval's good raw values (not time-weighted)
    TIME_AVERAGE = "time_average"  # time-weighted: Part 13 TimeAverage2 (simple bounds, stepped or sloped per tag)
    MINIMUM = "minimum"  # the smallest good raw value, stamped at the interval's start
    MAXIMUM = "maximum"
    MINIMUM_ACTUAL_TIME = "minimum_actual_time"  # stamped when it occurred
    MAXIMUM_ACTUAL_TIME = "maximum_actual_time"
    COUNT = "count"  # good raw values in the interval

    @property
    def numeric(self) -> bool:
        """Whether it needs numbers (strings have only Interpolative and Count)."""
        return self not in (Aggregate.INTERPOLATIVE, Aggregate.COUNT)


@dataclass(frozen=True)
class AggregateConfig:
    """Part 13's AggregateConfiguration. The defaults are the usual server defaults (OPC Foundation stack)."""

    treat_uncertain_as_bad: bool = True
    percent_data_bad: int = 100  # an interval with at least this % of bad data is BAD
    percent_data_good: int = 100  # ... with at least this % of good data is GOOD; between the two UNCERTAIN

    def __post_init__(self) -> None:
        for name in ("percent_data_bad", "percent_data_good"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 100:
                raise ValueError(f"{name} must be a whole percentage 0..100, not {value!r}")
        if self.percent_data_good < 100 - self.percent_data_bad:
            # Otherwise an interval could be both GOOD and BAD (Part 13 §4.2.1.2).
            raise ValueError("percent_data_good must be at least 100 - percent_data_bad")

    def usable(self, sample: Sample) -> bool:
        """Whether a raw value takes part in calculations: good, or uncertain when uncertain is not bad."""
        if sample.quality is Quality.BAD or not valid(sample.value):
            return False
        return sample.quality is Quality.GOOD or not self.treat_uncertain_as_bad

    def status(self, bad: float, good: float, total: float) -> Quality:
        """Part 13 §5.4.3.2: the quality of an interval from its amounts (counts or durations) of bad and good data."""
        if total <= 0:
            return Quality.BAD
        if bad > 0 and 100 * bad / total >= self.percent_data_bad - 1e-9:
            return Quality.BAD
        return Quality.GOOD if 100 * good / total >= self.percent_data_good - 1e-9 else Quality.UNCERTAIN


DEFAULT_CONFIG = AggregateConfig()


def valid(value: Any) -> bool:
    """A value that can be computed with (not a null, not NaN)."""
    return value is not None and not (isinstance(value, float) and math.isnan(value))


# -- intervals (Part 13 §5.4.2.2) --------------------------------------------------------------


class Interval(NamedTuple):
    """One processing interval: its timestamp, its span, and whether it is shorter than asked.

    Forward the span is [low, high) and the stamp `low`; backwards (time flowing back, Part 13)
    it is (low, high] and the stamp `high`: an interval holds its start and not its end.
    """

    stamp: float
    low: float
    high: float
    partial: bool = False

    @property
    def backward(self) -> bool:
        return self.stamp == self.high and self.low != self.high


def interval_count(start: float, end: float, interval: float) -> int:
    """How many intervals [start, end) makes; ValueError when start == end (Part 13: Bad_InvalidArgument)."""
    if start == end:
        raise ValueError("start and end are the same time: there is no interval")
    if interval < 0 or not math.isfinite(interval):
        raise ValueError("the processing interval must be zero (one interval) or positive")
    span = abs(end - start)
    if interval == 0 or interval >= span:
        return 1
    whole = math.floor(span / interval + 1e-9)
    return whole + (1 if span - whole * interval > span * 1e-12 else 0)


def intervals(start: float, end: float, interval: float, first: int = 0, count: int | None = None) -> Iterator[Interval]:
    """The intervals of a processed read, from number `first` on (at most `count`); backwards when start > end."""
    total = interval_count(start, end, interval)
    stop = total if count is None else min(total, first + count)
    span = abs(end - start)
    width = span if interval == 0 or interval >= span else interval
    forward = end > start
    for number in range(first, stop):
        offset = number * width
        near, far = offset, min(span, offset + width)
        partial = interval > 0 and far - near < interval * (1 - 1e-12)
        if forward:
            yield Interval(start + near, start + near, start + far if far < span else end, partial)
        else:
            yield Interval(start - near, start - far if far < span else end, start - near, partial)


# -- aggregates over one interval ---------------------------------------------------------------


def average(stamp: float, inside: Sequence[Sample], config: AggregateConfig) -> Result:
    """Part 13 Average: the mean of the usable raw values; the status counts values (PercentValues)."""
    if not inside:
        return Result(stamp, None, Quality.BAD, Flags.NO_DATA | Flags.CALCULATED)
    used = [s for s in inside if config.usable(s)]
    if not used:
        return Result(stamp, None, Quality.BAD, Flags.CALCULATED)
    quality = config.status(len(inside) - len(used), len(used), len(inside))
    value = math.fsum(float(s.value) for s in used) / len(used)
    return _calculated(stamp, value, quality, used)


def extreme(stamp: float, inside: Sequence[Sample], config: AggregateConfig, *, largest: bool, actual_time: bool) -> Result:
    """Part 13 Minimum / Maximum (and their ActualTime variants): the extreme usable raw value; the oldest on ties."""
    candidates = [s for s in inside if config.usable(s)]
    if not candidates:
        return Result(stamp, None, Quality.BAD, Flags.NO_DATA)
    best = candidates[0]
    for sample in candidates[1:]:
        if (sample.value > best.value) if largest else (sample.value < best.value):
            best = sample
    flags = Flags.NONE
    if sum(1 for s in candidates if s.value == best.value) > 1:
        flags |= Flags.MULTI_VALUE
    # Uncertain when bad values were skipped, or an uncertain value left out would have been the extreme.
    skipped_bad = any(s.quality is Quality.BAD or not valid(s.value) for s in inside)
    beyond = any(s.quality is Quality.UNCERTAIN and valid(s.value) and not config.usable(s)
                 and ((s.value > best.value) if largest else (s.value < best.value)) for s in inside)
    uncertain = skipped_bad or beyond or best.quality is Quality.UNCERTAIN
    if uncertain:
        flags |= Flags.SUB_NORMAL | Flags.CALCULATED
    elif not actual_time and best.time != stamp:
        flags |= Flags.CALCULATED  # the value of another instant, stamped at the interval's start
    quality = Quality.UNCERTAIN if uncertain else Quality.GOOD
    return Result(best.time if actual_time else stamp, best.value, quality, flags)


def count(stamp: float, inside: Sequence[Sample], config: AggregateConfig) -> Result:
    """Part 13 Count: how many usable raw values; the status counts values (PercentValues)."""
    used = [s for s in inside if config.usable(s)]
    quality = config.status(len(inside) - len(used), len(used), len(inside)) if inside else Quality.GOOD
    flags = Flags.CALCULATED | (Flags.SUB_NORMAL if quality is Quality.UNCERTAIN else Flags.NONE)
    return Result(stamp, len(used), quality, flags)


def time_average(stamp: float, low: float, high: float, start: Result, inside: Sequence[Sample], end: Result,
                 config: AggregateConfig, *, stepped: bool) -> Result:
    """Part 13 TimeAverage2: the area under the line through the simple bounding values and the raw values, over
    the time covered by usable data; the status weighs durations (PercentTime).

    `start` / `end` are the simple bounding values at `low` and `high`; `inside` the raw values in (low, high).
    A region [p, q) takes p's value when p is usable: held (stepped, or q not usable) or sloped towards q; it is
    uncertain when p is, or (sloped) when q is; it is bad when p is not usable.
    """
    points: list[Result | Sample] = [start, *inside, end]
    area = good = bad = 0.0
    any_uncertain = False
    for p, q in zip(points, points[1:]):
        width = min(q.time, high) - max(p.time, low)
        if width <= 0:
            continue
        p_ok = _bound_usable(p, config)
        q_ok = _bound_usable(q, config)
        if not p_ok:
            bad += width
            continue
        uncertain = p.quality is Quality.UNCERTAIN or (not stepped and q.quality is Quality.UNCERTAIN)
        if uncertain and config.treat_uncertain_as_bad:
            bad += width
            continue
        any_uncertain |= uncertain
        if stepped or not q_ok:
            area += float(p.value) * width
        else:
            area += (float(p.value) + float(q.value)) / 2 * width
        good += width
    if good <= 0:
        no_data = not inside and all(p.flags & Flags.NO_DATA for p in (start, end))
        return Result(stamp, None, Quality.BAD, Flags.CALCULATED | (Flags.NO_DATA if no_data else Flags.NONE))
    quality = config.status(bad, good, high - low)
    if quality is Quality.GOOD and any_uncertain:
        quality = Quality.UNCERTAIN
    if quality is Quality.BAD:
        return Result(stamp, None, quality, Flags.CALCULATED)
    flags = Flags.CALCULATED | (Flags.SUB_NORMAL if quality is Quality.UNCERTAIN else Flags.NONE)
    return Result(stamp, area / good, quality, flags)


def _bound_usable(point: Result | Sample, config: AggregateConfig) -> bool:
    return config.usable(Sample(point.time, point.value, point.quality))


def _calculated(stamp: float, value: float, quality: Quality, used: Sequence[Sample]) -> Result:
    if quality is Quality.BAD:
        return Result(stamp, None, quality, Flags.CALCULATED)
    if quality is Quality.GOOD and any(s.quality is Quality.UNCERTAIN for s in used):
        quality = Quality.UNCERTAIN  # an uncertain value took part: the result is no better (§5.4.3.2)
    flags = Flags.CALCULATED | (Flags.SUB_NORMAL if quality is Quality.UNCERTAIN else Flags.NONE)
    return Result(stamp, value, quality, flags)


# -- plots --------------------------------------------------------------------------------------


def decimate(times: Any, values: Any, start: float, end: float, buckets: int) -> list[Sample]:
    """At most two points per bucket — its minimum and its maximum, in time order — so no spike is lost."""
    import numpy as np

    if len(times) == 0:
        return []
    width = (end - start) / buckets
    index = np.minimum(((times - start) / width).astype(np.int64), buckets - 1)
    order = np.lexsort((times, values, index))  # by bucket, then value, then time
    sorted_index = index[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = sorted_index[1:] != sorted_index[:-1]
    last = np.ones(len(order), dtype=bool)
    last[:-1] = sorted_index[1:] != sorted_index[:-1]
    chosen = np.unique(np.concatenate([order[first], order[last]]))
    chosen = chosen[np.argsort(times[chosen], kind="stable")]
    return [Sample(float(times[i]), float(values[i])) for i in chosen]
