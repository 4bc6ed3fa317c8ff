"""Processed reads (OPC UA Part 13), values at times and Part 11 raw reads, against hand-computed vectors —
on SQLite and on a real PostgreSQL server (the store tests' `storage_settings`)."""

from __future__ import annotations

import math
from typing import Any

import pytest

from softplc.adapters.history.aggregates import Aggregate, AggregateConfig, Flags, Result, intervals
from softplc.adapters.history.reads import InvalidContinuation, read_processed, read_raw
from softplc.core.tags import Quality
from softplc.storage import StorageSettings
from tests.adapters.history.test_history_store import T0, Store

GOOD, UNCERTAIN, BAD = Quality.GOOD, Quality.UNCERTAIN, Quality.BAD
CALC, INTERP, PARTIAL, MULTI = Flags.CALCULATED, Flags.INTERPOLATED, Flags.PARTIAL, Flags.MULTI_VALUE
NO_DATA, SUB, NO_BOUND, RAW = Flags.NO_DATA, Flags.SUB_NORMAL, Flags.NO_BOUND, Flags.NONE


@pytest.fixture
def store(storage_settings: StorageSettings):
    opened = Store(storage_settings)
    yield opened
    opened.close()


def seen(results: list[Result]) -> list[tuple[float, Any, Quality, Flags]]:
    """(seconds after T0, value rounded, quality, flags) of each result."""
    return [(r.time - T0, None if r.value is None else round(r.value, 6), r.quality, r.flags) for r in results]


def test_intervals_follow_part_13_table_12() -> None:
    assert [(i.low, i.high, i.partial) for i in intervals(0, 30, 10)] == [(0, 10, False), (10, 20, False), (20, 30, False)]
    assert [(i.low, i.high, i.partial) for i in intervals(0, 25, 10)] == [(0, 10, False), (10, 20, False), (20, 25, True)]
    assert [(i.low, i.high, i.partial) for i in intervals(0, 25, 0)] == [(0, 25, False)]  # 0: one interval
    assert [(i.low, i.high, i.partial) for i in intervals(0, 25, 60)] == [(0, 25, True)]  # longer than the range
    assert [(i.stamp, i.low, i.high, i.partial) for i in intervals(25, 0, 10)] == [(25, 15, 25, False), (15, 5, 15, False), (5, 0, 5, True)]
    with pytest.raises(ValueError):
        list(intervals(5, 5, 1))  # Bad_InvalidArgument


def test_average_is_the_mean_of_raw_values_and_time_average_is_time_weighted(store: Store) -> None:
    # level (sloped): 0 at 0 s, 10 at 10 s, 10 at 30 s.   count (stepped): the same values.
    store.write([(name, T0 + t, v, GOOD) for name in ("level", "count") for t, v in ((0, 0), (10, 10), (30, 10))])
    processed = store.reader.processed
    # Part 13 Average: (0 + 10) / 2; nothing stored in [15, 30): Bad_NoData.
    assert seen(processed("level", T0, T0 + 30, 15, Aggregate.AVERAGE)) == [(0, 5.0, GOOD, CALC), (15, None, BAD, NO_DATA | CALC)]
    # TimeAverage2: [0, 15) trapezoid 0→10 over 10 s (area 50) + 10 for 5 s (50) = 100 / 15; [15, 30): 10.
    assert seen(processed("level", T0, T0 + 30, 15, Aggregate.TIME_AVERAGE)) == [(0, round(100 / 15, 6), GOOD, CALC), (15, 10.0, GOOD, CALC)]
    # Stepped: 0 for 10 s, 10 for 5 s.
    assert seen(processed("count", T0, T0 + 30, 15, Aggregate.TIME_AVERAGE)) == [(0, round(50 / 15, 6), GOOD, CALC), (15, 10.0, GOOD, CALC)]
    # A last, shorter interval is Partial (Average never says so).
    assert seen(processed("level", T0, T0 + 25, 10, Aggregate.TIME_AVERAGE))[2] == (20, 10.0, GOOD, CALC | PARTIAL)
    assert seen(processed("level", T0, T0 + 25, 10, Aggregate.AVERAGE))[2] == (20, None, BAD, NO_DATA | CALC)


def test_minimum_maximum_interpolative_and_count(store: Store) -> None:
    store.write([("level", T0 + t, v, GOOD) for t, v in ((0, 0), (10, 10), (30, 10))])
    processed = store.reader.processed
    # The minimum is the raw value at the interval's start: Raw; the maximum of [0, 15) is stamped 0: Calculated.
    assert seen(processed("level", T0, T0 + 30, 15, Aggregate.MINIMUM)) == [(0, 0.0, GOOD, RAW), (15, None, BAD, NO_DATA)]
    assert seen(processed("level", T0, T0 + 15, 15, Aggregate.MAXIMUM)) == [(0, 10.0, GOOD, CALC)]
    assert seen(processed("level", T0, T0 + 15, 15, Aggregate.MAXIMUM_ACTUAL_TIME)) == [(10, 10.0, GOOD, RAW)]
    # 10 twice in [0, 40): MultiValue; the actual time is the oldest.
    assert seen(processed("level", T0, T0 + 40, 0, Aggregate.MAXIMUM)) == [(0, 10.0, GOOD, CALC | MULTI)]
    assert seen(processed("level", T0, T0 + 40, 0, Aggregate.MAXIMUM_ACTUAL_TIME)) == [(10, 10.0, GOOD, MULTI)]
    assert seen(processed("level", T0, T0 + 20, 5, Aggregate.INTERPOLATIVE)) == [
        (0, 0.0, GOOD, RAW), (5, 5.0, GOOD, INTERP), (10, 10.0, GOOD, RAW), (15, 10.0, GOOD, INTERP)]
    # After the last value it is held (stepped extrapolation): Uncertain_DataSubNormal.
    assert seen(processed("level", T0 + 35, T0 + 36, 0, Aggregate.INTERPOLATIVE)) == [(35, 10.0, UNCERTAIN, INTERP | SUB)]
    assert [r.value for r in processed("level", T0, T0 + 30, 10, Aggregate.COUNT)] == [1, 1, 0]
    # Backwards (start > end): intervals (15, 30] and (0, 15], later first; an interval holds its start.
    assert seen(processed("level", T0 + 30, T0, 15, Aggregate.MINIMUM)) == [(30, 10.0, GOOD, RAW), (15, 10.0, GOOD, CALC)]
    with pytest.raises(ValueError, match="same time"):
        processed("level", T0, T0, 1, Aggregate.AVERAGE)


def test_bad_and_uncertain_values_make_results_uncertain_as_part_13_says(store: Store) -> None:
    # 0 good at 0, 5 BAD at 10, 10 good at 20, 20 UNCERTAIN at 30, 30 good at 40.
    store.write([("level", T0 + t, float(v), q) for t, v, q in ((0, 0, GOOD), (10, 5, BAD), (20, 10, GOOD), (30, 20, UNCERTAIN), (40, 30, GOOD))])
    processed, lenient = store.reader.processed, AggregateConfig(treat_uncertain_as_bad=False)
    # Average (server defaults: uncertain is bad, 100 % good needed): (0 + 10 + 30) / 3 of 5 values.
    assert seen(processed("level", T0, T0 + 50, 0, Aggregate.AVERAGE)) == [(0, round(40 / 3, 6), UNCERTAIN, CALC | SUB)]
    assert seen(processed("level", T0, T0 + 50, 0, Aggregate.AVERAGE, config=lenient)) == [(0, 15.0, UNCERTAIN, CALC | SUB)]
    # [0, 25): 1 bad of 3 values; with percent_data_good 60 the interval is Good, with percent_data_bad 30 Bad.
    assert seen(processed("level", T0, T0 + 25, 0, Aggregate.AVERAGE)) == [(0, 5.0, UNCERTAIN, CALC | SUB)]
    assert seen(processed("level", T0, T0 + 25, 0, Aggregate.AVERAGE, config=AggregateConfig(True, 50, 60))) == [(0, 5.0, GOOD, CALC)]
    assert seen(processed("level", T0, T0 + 25, 0, Aggregate.AVERAGE, config=AggregateConfig(True, 30, 80))) == [(0, None, BAD, CALC)]
    # Minimum/Maximum: bad values skipped → Uncertain; an uncertain value left out beyond the maximum too.
    assert seen(processed("level", T0, T0 + 50, 0, Aggregate.MINIMUM)) == [(0, 0.0, UNCERTAIN, CALC | SUB)]
    assert seen(processed("level", T0 + 20, T0 + 35, 0, Aggregate.MINIMUM)) == [(20, 10.0, GOOD, RAW)]
    assert seen(processed("level", T0 + 20, T0 + 35, 0, Aggregate.MAXIMUM)) == [(20, 10.0, UNCERTAIN, CALC | SUB)]
    assert seen(processed("level", T0 + 20, T0 + 35, 0, Aggregate.MAXIMUM, config=lenient)) == [(20, 20.0, UNCERTAIN, CALC | SUB)]
    assert seen(processed("level", T0, T0 + 50, 0, Aggregate.COUNT)) == [(0, 3, UNCERTAIN, CALC | SUB)]
    # Interpolative skips bad values (and, by default, uncertain ones): Uncertain_DataSubNormal.
    assert seen(processed("level", T0 + 5, T0 + 40, 5, Aggregate.INTERPOLATIVE)) == [
        (5, 2.5, UNCERTAIN, INTERP | SUB), (10, 5.0, UNCERTAIN, INTERP | SUB), (15, 7.5, UNCERTAIN, INTERP | SUB),
        (20, 10.0, GOOD, RAW), (25, 15.0, UNCERTAIN, INTERP | SUB), (30, 20.0, UNCERTAIN, INTERP | SUB), (35, 25.0, UNCERTAIN, INTERP | SUB)]
    # TimeAverage2 over [0, 40): 0 held over [0, 10) (the next value is bad); [10, 20) bad; [20, 40) uncertain,
    # which the defaults count as bad: 0 over the 10 good seconds, 75 % bad → Uncertain.
    assert seen(processed("level", T0, T0 + 40, 0, Aggregate.TIME_AVERAGE)) == [(0, 0.0, UNCERTAIN, CALC | SUB)]
    # Uncertain as good: + trapezoids 10→20 and 20→30 over [20, 40) = 150 + 250, over 30 s.
    assert seen(processed("level", T0, T0 + 40, 0, Aggregate.TIME_AVERAGE, config=lenient)) == [(0, round(400 / 30, 6), UNCERTAIN, CALC | SUB)]


def test_values_at_times_with_interpolated_or_simple_bounds(store: Store) -> None:
    store.write([("level", T0 + t, float(v), q) for t, v, q in ((0, 0, GOOD), (10, 5, BAD), (20, 10, GOOD), (30, 20, UNCERTAIN))]
                + [("count", T0 + t, v, GOOD) for t, v in ((0, 0), (10, 10))])
    at_time = store.reader.at_time
    times = [T0 + t for t in (-5, 0, 5, 15, 25, 35)]
    assert seen(at_time("level", times)) == [
        (-5, None, BAD, NO_DATA), (0, 0.0, GOOD, RAW), (5, 2.5, UNCERTAIN, INTERP | SUB), (15, 7.5, UNCERTAIN, INTERP | SUB),
        (25, 10.0, UNCERTAIN, INTERP | SUB), (35, 10.0, UNCERTAIN, INTERP | SUB)]  # 25, 35: after the last good value
    # Simple bounds: the value right before; a bad one gives Bad_NoData; a bad or uncertain one after: held, Uncertain.
    assert seen(at_time("level", times, simple_bounds=True)) == [
        (-5, None, BAD, NO_DATA), (0, 0.0, GOOD, RAW), (5, 0.0, UNCERTAIN, INTERP | SUB), (15, None, BAD, NO_DATA),
        (25, 10.0, UNCERTAIN, INTERP | SUB), (35, None, BAD, NO_DATA)]
    lenient = AggregateConfig(treat_uncertain_as_bad=False)
    assert seen(at_time("level", [T0 + 25, T0 + 30], simple_bounds=True, config=lenient)) == [
        (25, 15.0, UNCERTAIN, INTERP | SUB), (30, 20.0, UNCERTAIN, RAW)]
    # Stepped: the value before holds; after the last one it is extrapolated.
    assert seen(at_time("count", [T0 + 2.5, T0 + 10, T0 + 15])) == [(2.5, 0, GOOD, INTERP), (10, 10, GOOD, RAW), (15, 10, UNCERTAIN, INTERP | SUB)]


# -- Part 11 raw reads: Table 1 of §4.4 (values at 5:00, 5:02, 5:03, 5:05, 5:06 → seconds 0, 2, 3, 5, 6) --------

FIRST, LAST = "FIRST", "LAST"


def raw(store: Store, start: float | None, end: float | None, limit: int = 0, bounds: bool = False) -> list[list[Any]]:
    """Every page of a raw read, as seconds (FIRST / LAST for a bound not found)."""
    pages, token = [], None
    while True:
        results, token = read_raw(store.reader, "level", None if start is None else T0 + start, None if end is None else T0 + end,
                                  limit=limit, bounds=bounds, token=token)
        pages.append([("LAST" if r.time - T0 == end else "FIRST") if r.flags & NO_BOUND else r.time - T0 for r in results])
        if token is None:
            return pages


@pytest.mark.parametrize(("start", "end", "limit", "bounds", "expected"), [
    (0, 5, 0, True, [[0, 2, 3, 5]]),
    (0, 5, 0, False, [[0, 2, 3]]),
    (1, 4, 0, True, [[0, 2, 3, 5]]),
    (1, 4, 0, False, [[2, 3]]),
    (5, 0, 0, True, [[5, 3, 2, 0]]),
    (5, 0, 0, False, [[5, 3, 2]]),
    (4, 1, 0, True, [[5, 3, 2, 0]]),
    (4, 1, 0, False, [[3, 2]]),
    (-1, 5, 0, True, [[FIRST, 0, 2, 3, 5]]),
    (1, 7, 0, True, [[0, 2, 3, 5, 6, LAST]]),
    (1, 7, 0, False, [[2, 3, 5, 6]]),
    (0, 5, 3, True, [[0, 2, 3], [5]]),  # bounds count towards the limit
    (-1, 5, 3, True, [[FIRST, 0, 2], [3, 5]]),
    (1, 7, 2, True, [[0, 2], [3, 5], [6, LAST]]),
    (0, None, 3, False, [[0, 2, 3], [5, 6]]),  # only a start: forward to the end of the history
    (None, 5, 3, False, [[5, 3, 2], [0]]),  # only an end: backwards from it
    (3, 3, 0, False, [[3]]),  # the same instant twice: its value
])
def test_raw_reads_follow_part_11(store: Store, start, end, limit, bounds, expected) -> None:
    store.write([("level", T0 + t, float(t), GOOD) for t in (0, 2, 3, 5, 6)])
    assert raw(store, start, end, limit, bounds) == expected


def test_continuations_are_checked_and_processed_reads_go_on_page_by_page(store: Store) -> None:
    store.write([("level", T0 + t, float(t), GOOD) for t in range(10)])
    _, token = read_raw(store.reader, "level", T0, T0 + 10, limit=3)
    assert token is not None
    for bogus in ("made-up", token + "x", token[:-4], "h1.e30"):
        with pytest.raises(InvalidContinuation):
            read_raw(store.reader, "level", T0, T0 + 10, limit=3, token=bogus)
    with pytest.raises(InvalidContinuation):
        read_raw(store.reader, "count", T0, T0 + 10, limit=3, token=token)  # another tag's
    config = AggregateConfig()
    whole, _ = read_processed(store.reader, "level", T0, T0 + 10, 2, Aggregate.AVERAGE, config=config)
    pages, token = [], None
    while True:
        page, token = read_processed(store.reader, "level", T0, T0 + 10, 2, Aggregate.AVERAGE, config=config, limit=2, token=token)
        pages.append(page)
        if token is None:
            break
    assert [len(page) for page in pages] == [2, 2, 1] and [r for page in pages for r in page] == whole
    assert [r.value for r in whole] == [0.5, 2.5, 4.5, 6.5, 8.5]
    assert math.isclose(whole[0].time, T0)


def test_a_read_without_a_limit_comes_in_pages_of_max_values(store: Store) -> None:
    from softplc.adapters.history.reads import MAX_VALUES

    store.write([("level", T0 + t * 0.1, float(t), GOOD) for t in range(2 * MAX_VALUES + 5)])
    sizes, token, seen_values = [], None, []
    while True:
        results, token = read_raw(store.reader, "level", T0, None, token=token)
        sizes.append(len(results))
        seen_values += [r.value for r in results]
        if token is None:
            break
    assert sizes == [MAX_VALUES, MAX_VALUES, 5] and seen_values == [float(t) for t in range(2 * MAX_VALUES + 5)]
