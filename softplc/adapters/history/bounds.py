"""Bounding values: a tag's value at an instant between stored samples (OPC UA Part 13 §3.1.8, §3.1.9).

*Interpolated* bounding values skip bad data: the line between the nearest usable values before
and after (sloped), or the one before (stepped); Uncertain_DataSubNormal when bad data was skipped
or a neighbour is uncertain; after the last value the last one is held (stepped extrapolation) and
is Uncertain_DataSubNormal; with no usable value before, Bad_NoData. Interpolative, ReadAtTime
and the interval bounds of TimeAverage use them.

*Simple* bounding values use the nearest values whatever their quality: a bad value before (or at)
the instant gives Bad_NoData, an uncertain neighbour Uncertain_DataSubNormal (ReadAtTime with
useSimpleBounds, and TimeAverage2's bounds).
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

from softplc.adapters.history.aggregates import DEFAULT_CONFIG, AggregateConfig, Flags, Result, Sample
from softplc.core.tags import Quality


class Series:
    """A tag's samples in time order, with the searches bounding values need."""

    def __init__(self, samples: Sequence[Sample]) -> None:
        self.samples = list(samples)
        self.times = [s.time for s in self.samples]

    def between(self, low: float, high: float) -> list[Sample]:
        """The samples in [low, high)."""
        return self.samples[bisect.bisect_left(self.times, low):bisect.bisect_left(self.times, high)]

    def between_backward(self, low: float, high: float) -> list[Sample]:
        """The samples in (low, high]."""
        return self.samples[bisect.bisect_right(self.times, low):bisect.bisect_right(self.times, high)]

    def inside(self, low: float, high: float) -> list[Sample]:
        """The samples strictly between low and high."""
        return self.samples[bisect.bisect_right(self.times, low):bisect.bisect_left(self.times, high)]

    def at(self, when: float) -> list[Sample]:
        return self.samples[bisect.bisect_left(self.times, when):bisect.bisect_right(self.times, when)]


def interpolated_bound(series: Series, when: float, *, stepped: bool, config: AggregateConfig = DEFAULT_CONFIG) -> Result:
    """The value at `when` from the nearest usable values around it (see the module docstring)."""
    samples, times = series.samples, series.times
    first_at = bisect.bisect_left(times, when)
    after_at = bisect.bisect_right(times, when)
    for sample in samples[first_at:after_at]:
        if config.usable(sample):
            return Result(when, sample.value, sample.quality)  # a raw value at that instant
    skipped = after_at > first_at  # a value at that instant that cannot be used
    index = first_at - 1
    while index >= 0 and not config.usable(samples[index]):
        skipped = True
        index -= 1
    if index < 0:
        return Result(when, None, Quality.BAD, Flags.NO_DATA)
    before = samples[index]
    index = after_at
    skipped_after = False
    while index < len(samples) and not config.usable(samples[index]):
        skipped_after = True
        index += 1
    after = samples[index] if index < len(samples) else None
    if after is None:  # after the end of the data: hold the last value (stepped extrapolation)
        return Result(when, before.value, Quality.UNCERTAIN, Flags.INTERPOLATED | Flags.SUB_NORMAL)
    if stepped:
        value = before.value
        uncertain = skipped or before.quality is Quality.UNCERTAIN
    else:
        value = _line(before, after, when)
        uncertain = skipped or skipped_after or Quality.UNCERTAIN in (before.quality, after.quality)
    if uncertain:
        return Result(when, value, Quality.UNCERTAIN, Flags.INTERPOLATED | Flags.SUB_NORMAL)
    return Result(when, value, Quality.GOOD, Flags.INTERPOLATED)


def simple_bound(series: Series, when: float, *, stepped: bool, config: AggregateConfig = DEFAULT_CONFIG) -> Result:
    """The value at `when` from the values right before and after it, whatever their quality."""
    samples, times = series.samples, series.times
    first_at = bisect.bisect_left(times, when)
    after_at = bisect.bisect_right(times, when)
    if after_at > first_at:
        sample = samples[first_at]
        if not config.usable(sample):
            return Result(when, None, Quality.BAD, Flags.NO_DATA)
        return Result(when, sample.value, sample.quality)
    if first_at == 0 or not config.usable(samples[first_at - 1]):
        return Result(when, None, Quality.BAD, Flags.NO_DATA)
    before = samples[first_at - 1]
    after = samples[after_at] if after_at < len(samples) else None
    uncertain = before.quality is Quality.UNCERTAIN
    if after is None:  # after the end of the data: hold the last value
        return Result(when, before.value, Quality.UNCERTAIN, Flags.INTERPOLATED | Flags.SUB_NORMAL)
    if stepped or not config.usable(after):
        value = before.value
        uncertain |= not stepped  # sloped towards a bad value: only the value before is known
    else:
        value = _line(before, after, when)
        uncertain |= after.quality is Quality.UNCERTAIN
    if uncertain:
        return Result(when, value, Quality.UNCERTAIN, Flags.INTERPOLATED | Flags.SUB_NORMAL)
    return Result(when, value, Quality.GOOD, Flags.INTERPOLATED)


def _line(before: Sample, after: Sample, when: float) -> float:
    if after.time <= before.time:
        return float(before.value)
    fraction = (when - before.time) / (after.time - before.time)
    return float(before.value) + (float(after.value) - float(before.value)) * fraction
