"""Reading history: raw values, plots decimated to at most N points, processed aggregates, values at times.

`HistoryReader(database, plant)` opens its own connection and may be used from any thread (one
call at a time; calls block on I/O, so from the event loop use `clock.run_blocking`). What an
OPC UA HistoryRead needs: `historized()`, `raw()` with a limit, a `Continuation`, bounds and
either direction, `processed()` with Part 13 aggregates, `at_time()`; what a trend page needs:
`plot()`. Ranges are half-open, [start, end) — reading backwards, (end, start].
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from softplc.adapters.history import aggregates
from softplc.adapters.history.aggregates import (
    DEFAULT_CONFIG,
    Aggregate,
    AggregateConfig,
    Flags,
    Result,
    Sample,
    decimate,
    intervals,
)
from softplc.adapters.history.bounds import Series, interpolated_bound, simple_bound
from softplc.adapters.history.store import LEVELS, QUALITIES, TagInfo
from softplc.core.tags import Quality
from softplc.storage import Database, StorageError

DEFAULT_PLOT_POINTS = 2000


class Continuation(NamedTuple):
    """Where a limited raw read goes on: at `time`, after the first `skip` samples stamped exactly then."""

    time: float
    skip: int = 0


@dataclass
class RawPage:
    """Raw samples of one read, the bounding values if asked for, and where to go on (None: done).

    Reading backwards the bounds are mirrored: `before` is the first sample after start, `after`
    the last sample at or before end.
    """

    samples: list[Sample]
    continuation: Continuation | None = None
    before: Sample | None = None  # the last sample before start (a bound)
    after: Sample | None = None  # the first sample at or after end (a bound)


@dataclass
class Plot:
    """Points for a trend: the raw samples, or min/max per bucket when there are more than asked for."""

    samples: list[Sample] = field(default_factory=list)
    decimated: bool = False
    bucket: float = 0.0  # bucket width in seconds when decimated


class UnknownTag(LookupError):
    """The tag has no history in this store (never recorded, or another plant's)."""


class HistoryReader:
    """Queries one plant's history in a store (see module docstring)."""

    def __init__(self, database: Database, plant: str) -> None:
        self.database = database
        self.plant = plant
        self._lock = threading.Lock()
        self._connection: Any = None

    def close(self) -> None:
        with self._lock:
            if self._connection is not None:
                self._connection.close()
                self._connection = None

    # -- what is there --------------------------------------------------------------------

    def historized(self) -> dict[str, TagInfo]:
        """Every tag of this plant that has history, by name."""
        rows = self._query("SELECT name, type, unit, stepped FROM history_tags WHERE plant = ? ORDER BY name", (self.plant,))
        return {name: TagInfo(name, kind, unit, bool(stepped)) for name, kind, unit, stepped in rows}

    def plants(self) -> list[str]:
        return [row[0] for row in self._query("SELECT DISTINCT plant FROM history_tags ORDER BY plant", ())]

    def span(self, tag: str) -> tuple[float, float] | None:
        """Times of the first and last stored sample of `tag` that hold a value (not the BAD end of a recording), or None."""
        tag_id, info = self._tag(tag)
        first = self._edge(tag_id, info, -math.inf, before=False, max_quality=1)
        last = self._edge(tag_id, info, math.inf, before=True, max_quality=1)
        return (first.time, last.time) if first and last else None

    # -- raw ------------------------------------------------------------------------------

    def raw(self, tag: str, start: float, end: float, *, limit: int | None = None,
            continuation: Continuation | None = None, bounds: bool = False, reverse: bool = False) -> RawPage:
        """Samples in [start, end) in time order — with `reverse`, in (end, start] newest first; at most
        `limit`, then a continuation to pass back."""
        tag_id, info = self._tag(tag)
        begin, skip = (continuation.time, continuation.skip) if continuation else (start, 0)
        wanted = None if limit is None else limit + 1  # one more tells whether the read goes on
        samples: list[Sample] = []
        if reverse:
            tables = list(reversed(self._partitions(end, begin, inclusive=True)))
            condition, order = "time > ? AND time <= ?", "DESC"
            arguments: tuple[float, float] = (end, begin)
        else:
            tables = self._partitions(begin, end)
            condition, order = "time >= ? AND time < ?", "ASC"
            arguments = (begin, end)
        for table in tables:
            need = None if wanted is None else wanted - len(samples) + skip
            sql = (f"SELECT time, value, text, quality FROM {table} WHERE tag = ? AND {condition} "
                   f"ORDER BY time {order}, quality {order}, value {order}, text {order}")
            rows = self._query(sql + (f" LIMIT {int(need)}" if need is not None else ""), (tag_id, *arguments))
            converted = [_sample(row, info) for row in rows]
            if skip:
                dropped = min(skip, len(converted))
                converted = converted[dropped:]
                skip -= dropped
            samples.extend(converted)
            if wanted is not None and len(samples) >= wanted:
                break
        page = RawPage(samples)
        if limit is not None and len(samples) > limit:
            del samples[limit:]
            last = samples[-1].time
            same = sum(1 for sample in samples if sample.time == last)
            if continuation is not None and last == continuation.time:
                same += continuation.skip
            page.continuation = Continuation(last, same)
        if bounds:
            if reverse:
                page.before = self._edge(tag_id, info, start, before=False, inclusive=False)
                page.after = self._edge(tag_id, info, end, before=True, inclusive=True)
            else:
                page.before = self._edge(tag_id, info, start, before=True)
                page.after = self._edge(tag_id, info, end, before=False)
        return page

    # -- plot -----------------------------------------------------------------------------

    def plot(self, tag: str, start: float, end: float, max_points: int = DEFAULT_PLOT_POINTS) -> Plot:
        """At most `max_points` points over [start, end): raw when they fit, else min and max per bucket.

        Long ranges read the 10-second, per-minute or per-hour min/max cells instead of every sample; edge
        cells that straddle start or end are read raw, so every extreme inside the range is kept.
        """
        import numpy as np

        if max_points < 2:
            raise ValueError("a plot needs at least 2 points")
        tag_id, info = self._tag(tag)
        if end <= start:
            return Plot()
        if not info.numeric:
            return Plot(self.raw(tag, start, end, limit=max_points).samples)
        buckets = max_points // 2
        width = (end - start) / buckets
        cell_width, suffix = 0.0, ""
        for level_suffix, level_width in LEVELS:
            if level_width <= width:
                cell_width, suffix = level_width, level_suffix
        if not suffix:
            page = self.raw(tag, start, end, limit=max_points)
            if page.continuation is None:
                return Plot(page.samples)
            rows = self._numeric_rows(tag_id, start, end)
            times, values = np.array([r[0] for r in rows], dtype=float), np.array([r[1] for r in rows], dtype=float)
            return Plot(self._with_gaps(tag_id, decimate(times, values, start, end, buckets), start, end, width), decimated=True, bucket=width)
        inner_start = math.ceil(start / cell_width) * cell_width
        inner_end = max(inner_start, math.floor(end / cell_width) * cell_width)
        edges = self._numeric_rows(tag_id, start, inner_start) + self._numeric_rows(tag_id, inner_end, end)
        cells: list[tuple[Any, ...]] = []
        for table in self._partitions(inner_start, inner_end):
            cells += self._query(f"SELECT count, tmin, vmin, tmax, vmax FROM {table}_{suffix} WHERE tag = ? AND cell >= ? AND cell < ?",
                                 (tag_id, inner_start, inner_end))
        total = len(edges) + sum(int(cell[0]) for cell in cells)
        if total <= max_points:
            return Plot(self.raw(tag, start, end).samples)
        times = np.array([row[0] for row in edges] + [c[1] for c in cells] + [c[3] for c in cells], dtype=float)
        values = np.array([row[1] for row in edges] + [c[2] for c in cells] + [c[4] for c in cells], dtype=float)
        return Plot(self._with_gaps(tag_id, decimate(times, values, start, end, buckets), start, end, width), decimated=True, bucket=width)

    # -- processed and at time -------------------------------------------------------------

    def processed(self, tag: str, start: float, end: float, interval: float, aggregate: Aggregate, *,
                  config: AggregateConfig = DEFAULT_CONFIG, first: int = 0, count: int | None = None) -> list[Result]:
        """One Part 13 aggregate per interval (OPC UA ReadProcessed), from interval number `first` (at most `count`).

        Intervals as Part 13 §5.4.2.2 makes them (`aggregates.intervals`): `interval` 0 is one
        interval; start > end reads backwards. ValueError for start == end, a negative interval,
        or an aggregate that needs numbers on a string tag.
        """
        tag_id, info = self._tag(tag)
        if aggregate.numeric and not info.numeric:
            raise ValueError(f"aggregate {aggregate.value} needs a numeric tag; {tag} is a {info.type}")
        chosen = list(intervals(start, end, interval, first, count))
        if not chosen:
            return []
        low, high = min(i.low for i in chosen), max(i.high for i in chosen)
        series = self._series(tag_id, info, low, high, config)
        return [_aggregate(aggregate, series, span, config, stepped=info.stepped) for span in chosen]

    def at_time(self, tag: str, times: Iterable[float], *, simple_bounds: bool = False,
                config: AggregateConfig = DEFAULT_CONFIG) -> list[Result]:
        """The value at each time (OPC UA ReadAtTime): the stored one (flags NONE), else a bounding value —
        interpolated (default) or simple — flagged INTERPOLATED; BAD with NO_DATA where there is none."""
        tag_id, info = self._tag(tag)
        bound = simple_bound if simple_bounds else interpolated_bound
        results = []
        for when in times:
            series = self._series(tag_id, info, when, when, config, inclusive=True)
            results.append(bound(series, when, stepped=info.stepped, config=config))
        return results

    # -- internals ------------------------------------------------------------------------

    def _series(self, tag_id: int, info: TagInfo, low: float, high: float, config: AggregateConfig,
                *, inclusive: bool = False) -> Series:
        """The samples from the last usable one before `low` to the first usable one after `high` (bounds need them)."""
        limit = 0 if config.treat_uncertain_as_bad else 1
        first = self._edge(tag_id, info, low, before=True, max_quality=limit)
        last = self._edge(tag_id, info, high, before=False, max_quality=limit, strictly_after=inclusive)
        begin = first.time if first is not None else low
        stop = last.time if last is not None else high
        rows: list[tuple[Any, ...]] = []
        for table in self._partitions(begin, stop, inclusive=True):
            rows += self._query(f"SELECT time, value, text, quality FROM {table} WHERE tag = ? AND time >= ? AND time <= ? "
                                "ORDER BY time, quality, value, text", (tag_id, begin, stop))
        return Series([_sample(row, info) for row in rows])

    def _with_gaps(self, tag_id: int, samples: list[Sample], start: float, end: float, width: float) -> list[Sample]:
        """Decimated `samples` with the first BAD sample of each bucket that has one: where the plot has no data."""
        gaps: list[Sample] = []
        for table in self._partitions(start, end):
            rows = self._query(f"SELECT MIN(time) FROM {table} WHERE tag = ? AND time >= ? AND time < ? AND quality = 2 "
                               "GROUP BY CAST((time - ?) / ? AS INTEGER)", (tag_id, start, end, start, width))
            gaps += [Sample(float(when), math.nan, Quality.BAD) for (when,) in rows]
        return sorted(samples + gaps, key=lambda sample: sample.time) if gaps else samples

    def _numeric_rows(self, tag_id: int, start: float, end: float) -> list[tuple[float, float]]:
        rows: list[tuple[float, float]] = []
        if end <= start:
            return rows
        for table in self._partitions(start, end):
            rows += self._query(f"SELECT time, value FROM {table} WHERE tag = ? AND time >= ? AND time < ? AND quality < 2 AND value IS NOT NULL ORDER BY time",
                                (tag_id, start, end))
        return rows

    def _edge(self, tag_id: int, info: TagInfo, when: float, *, before: bool, inclusive: bool = False,
              max_quality: int | None = None, strictly_after: bool = False) -> Sample | None:
        """The last sample before `when` (or at it, if inclusive), or the first at (unless strictly_after) or after it;
        with `max_quality` (0 good, 1 uncertain), only samples of that quality or better that hold a value."""
        relation = ("<=" if inclusive else "<") if before else (">" if strictly_after else ">=")
        order = "DESC" if before else "ASC"
        quality = "" if max_quality is None else f" AND quality <= {int(max_quality)} AND (value IS NOT NULL OR text IS NOT NULL)"
        bound = "start <= ?" if before else "stop > ?"
        moment = when if math.isfinite(when) else (1e300 if when > 0 else -1e300)
        partitions = self._query(f"SELECT name FROM history_partitions WHERE {bound} ORDER BY start {order}", (moment,))
        for (table,) in partitions:
            rows = self._query(f"SELECT time, value, text, quality FROM {table} WHERE tag = ? AND time {relation} ?{quality} "
                               f"ORDER BY time {order}, quality {order}, value {order}, text {order} LIMIT 1",
                               (tag_id, moment))
            if rows:
                return _sample(rows[0], info)
        return None

    def _tag(self, tag: str) -> tuple[int, TagInfo]:
        rows = self._query("SELECT id, type, unit, stepped FROM history_tags WHERE plant = ? AND name = ?", (self.plant, tag))
        if not rows:
            raise UnknownTag(f"no history of {tag} (plant {self.plant}) in {self.database.describe()}")
        tag_id, kind, unit, stepped = rows[0]
        return int(tag_id), TagInfo(tag, kind, unit, bool(stepped))

    def _partitions(self, start: float, end: float, *, inclusive: bool = False) -> list[str]:
        """The partitions holding times in [start, end) — [start, end] if inclusive — oldest first."""
        relation = "<=" if inclusive else "<"
        rows = self._query(f"SELECT name FROM history_partitions WHERE stop > ? AND start {relation} ? ORDER BY start", (start, end))
        return [name for (name,) in rows]

    def _query(self, sql: str, parameters: Sequence[Any]) -> list[tuple[Any, ...]]:
        with self._lock:
            try:
                return self._execute(sql, parameters)
            except Exception as error:
                if self._connection is None or not self.database.lost(self._connection, error):
                    raise
            # The server went away since the last read (a PostgreSQL restart): once more on a new
            # connection, so a reader never keeps answering "the connection is closed".
            connection, self._connection = self._connection, None
            _close_quietly(connection)
            return self._execute(sql, parameters)

    def _execute(self, sql: str, parameters: Sequence[Any]) -> list[tuple[Any, ...]]:
        if self._connection is None:
            if not self.database.exists():
                raise StorageError(f"no history store at {self.database.describe()}")
            self._connection = self.database.connect(readonly=True)
        connection = self._connection
        try:
            cursor = connection.cursor()
            cursor.execute(self.database.sql(sql), tuple(parameters))
            rows = cursor.fetchall()
        except Exception as error:
            if self.database.postgresql:
                _rollback_quietly(connection)
            if "history_" in str(error) and ("no such table" in str(error) or "does not exist" in str(error)):
                raise StorageError(f"{self.database.describe()} holds no history (no history tables)") from error
            raise
        if self.database.postgresql:
            connection.rollback()  # end the read transaction: no snapshot held between calls
        return rows


def _rollback_quietly(connection: Any) -> None:
    try:
        connection.rollback()
    except Exception:  # noqa: BLE001 — a lost connection: the error that lost it is what the caller sees
        pass


def _close_quietly(connection: Any) -> None:
    try:
        connection.close()
    except Exception:  # noqa: BLE001
        pass


def _sample(row: tuple[Any, ...], info: TagInfo) -> Sample:
    when, value, text, code = row
    quality = QUALITIES.get(int(code), Quality.BAD)
    if info.type == "string":
        return Sample(float(when), text if text is not None else "", quality)
    if value is None:
        return Sample(float(when), math.nan, quality)
    if info.type == "bool":
        return Sample(float(when), bool(value), quality)
    if info.type.startswith(("int", "uint")):
        return Sample(float(when), int(value), quality)
    return Sample(float(when), float(value), quality)


def _aggregate(aggregate: Aggregate, series: Series, span: aggregates.Interval, config: AggregateConfig, *, stepped: bool) -> Result:
    """One interval's value of `aggregate` (Part 13 §5.4.3); PARTIAL where Part 13 sets it for a short interval."""
    stamp, low, high = span.stamp, span.low, span.high
    if aggregate is Aggregate.INTERPOLATIVE:
        return interpolated_bound(series, stamp, stepped=stepped, config=config)
    inside = series.between_backward(low, high) if span.backward else series.between(low, high)
    if aggregate is Aggregate.AVERAGE:
        return aggregates.average(stamp, inside, config)  # Part 13 never sets Partial on an Average
    if aggregate is Aggregate.COUNT:
        result = aggregates.count(stamp, inside, config)
    elif aggregate is Aggregate.TIME_AVERAGE:
        start = simple_bound(series, low, stepped=stepped, config=config)
        end = simple_bound(series, high, stepped=stepped, config=config)
        result = aggregates.time_average(stamp, low, high, start, series.inside(low, high), end, config, stepped=stepped)
    else:
        largest = aggregate in (Aggregate.MAXIMUM, Aggregate.MAXIMUM_ACTUAL_TIME)
        actual = aggregate in (Aggregate.MINIMUM_ACTUAL_TIME, Aggregate.MAXIMUM_ACTUAL_TIME)
        result = aggregates.extreme(stamp, inside, config, largest=largest, actual_time=actual)
    return result._replace(flags=result.flags | Flags.PARTIAL) if span.partial else result
