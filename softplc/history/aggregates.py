"""Pure functions over samples: interpolation, and the OPC UA Part 13 aggregates per interval.

A tag's history is either *sloped* (a float: the value moves linearly between two stored
samples, as swinging-door compression assumes) or *stepped* (integers, booleans, strings: a value
holds until the next sample). A BAD sample starts a gap that lasts until the next good sample;
gaps are left out of averages (and make the result UNCERTAIN).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from typing import Any, NamedTuple

from softplc.tags import Quality


class Sample(NamedTuple):
    """One stored value of a tag."""

    time: float  # Unix seconds (simulated seconds for a --sim store)
    value: Any
    quality: Quality = Quality.GOOD


class Aggregate(enum.Enum):
    """The processed reads offered (OPC UA Part 13 names)."""

    AVERAGE = "average"  # time-weighted
    MINIMUM = "minimum"  # timestamp: the interval's start
    MAXIMUM = "maximum"
    MINIMUM_ACTUAL_TIME = "minimum_actual_time"  # timestamp: when the minimum occurred
    MAXIMUM_ACTUAL_TIME = "maximum_actual_time"
    INTERPOLATIVE = "interpolative"  # the value at the interval's start
    COUNT = "count"  # raw samples in the interval


def good(sample: Sample | None) -> bool:
    return sample is not None and sample.quality is not Quality.BAD


def interpolate(before: Sample | None, after: Sample | None, when: float, *, stepped: bool) -> Sample | None:
    """The value at `when` from the good samples around it (`before.time <= when`); None when there is none."""
    if not good(before):
        return None
    assert before is not None
    if before.time == when or stepped:
        return Sample(when, before.value, before.quality)
    if not good(after) or after is None or after.time <= before.time:
        # No later value to slope towards: hold the last one, but say it is not certain.
        return Sample(when, before.value, Quality.UNCERTAIN)
    fraction = (when - before.time) / (after.time - before.time)
    value = before.value + (after.value - before.value) * fraction
    worst = Quality.UNCERTAIN if Quality.UNCERTAIN in (before.quality, after.quality) else Quality.GOOD
    return Sample(when, value, worst)


def time_weighted_average(start: Sample | None, inside: Sequence[Sample], stop: Sample | None, end: float, *, stepped: bool) -> Sample:
    """Average over [start.time, end): `start` is the (interpolated) value at the interval's start,
    `inside` the raw samples strictly within, `stop` the (interpolated) value at `end`, if known.

    Returns BAD (no data) when no part of the interval is covered by good values.
    """
    begin = start.time if start is not None else (inside[0].time if inside else end)
    points = ([start] if start is not None else []) + list(inside)
    area = 0.0
    covered = 0.0
    for index, point in enumerate(points):
        following = points[index + 1] if index + 1 < len(points) else stop
        right = following.time if following is not None else end
        if not good(point) or right <= point.time:
            continue
        width = right - point.time
        if stepped or following is None or not good(following):
            area += float(point.value) * width
        else:
            area += (float(point.value) + float(following.value)) / 2 * width
        covered += width
    duration = end - (start.time if start is not None else begin)
    if covered <= 0:
        return Sample(begin, None, Quality.BAD)
    complete = start is not None and math.isclose(covered, duration, rel_tol=1e-9, abs_tol=1e-9)
    uncertain = any(p.quality is Quality.UNCERTAIN for p in points)
    return Sample(begin, area / covered, Quality.GOOD if complete and not uncertain else Quality.UNCERTAIN)


def extreme(inside: Sequence[Sample], *, largest: bool) -> Sample | None:
    """The smallest (or largest) good raw sample, the first one on ties; None when there is none."""
    best: Sample | None = None
    for sample in inside:
        if not good(sample) or sample.value is None or sample.value != sample.value:
            continue
        if best is None or (sample.value > best.value if largest else sample.value < best.value):
            best = sample
    return best


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
