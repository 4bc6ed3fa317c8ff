"""Reading history: raw values, plots decimated to at most N points, processed aggregates, values at times.

`HistoryReader(database, plant)` opens its own connection and may be used from any thread (one
call at a time; calls block on I/O, so from the event loop use `clock.run_blocking`). What an
OPC UA HistoryRead provider needs: `historized()`, `raw()` with a limit and a `Continuation`,
`processed()` with Part 13 aggregates, `at_time()`; what a trend page needs: `plot()`.
Ranges are half-open, [start, end).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from softplc.history.aggregates import Aggregate, Sample, decimate, extreme, interpolate, time_weighted_average
from softplc.history.store import LEVELS, QUALITIES, TagInfo
from softplc.storage import Database, StorageError
from softplc.tags import Quality

DEFAULT_PLOT_POINTS = 2000


class Continuation(NamedTuple):
    """Where a limited raw read goes on: at `time`, after the first `skip` samples stamped exactly then."""

    time: float
    skip: int = 0


@dataclass
class RawPage:
    """Raw samples of one read, the bounding values if asked for, and where to go on (None: done)."""

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
        """Times of the first and last stored sample of `tag`, or None."""
        tag_id, info = self._tag(tag)
        first = self._edge(tag_id, info, -math.inf, before=False)
        last = self._edge(tag_id, info, math.inf, before=True)
        return (first.time, last.time) if first and last else None

    # -- raw ------------------------------------------------------------------------------

    def raw(self, tag: str, start: float, end: float, *, limit: int | None = None,
            continuation: Continuation | None = None, bounds: bool = False) -> RawPage:
        """Samples in [start, end) in time order; at most `limit`, then a continuation to pass back."""
        tag_id, info = self._tag(tag)
        begin, skip = (continuation.time, continuation.skip) if continuation else (start, 0)
        wanted = None if limit is None else limit + 1  # one more tells whether the read goes on
        samples: list[Sample] = []
        for table in self._partitions(begin, end):
            need = None if wanted is None else wanted - len(samples) + skip
            sql = f"SELECT time, value, text, quality FROM {table} WHERE tag = ? AND time >= ? AND time < ? ORDER BY time, quality, value, text"
            rows = self._query(sql + (f" LIMIT {int(need)}" if need is not None else ""), (tag_id, begin, end))
            converted = [_sample(row, info) for row in rows]
            if skip:
                converted = converted[skip:]
                skip = 0
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
            return Plot(decimate(times, values, start, end, buckets), decimated=True, bucket=width)
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
        return Plot(decimate(times, values, start, end, buckets), decimated=True, bucket=width)

    # -- processed and at time -------------------------------------------------------------

    def processed(self, tag: str, start: float, end: float, interval: float, aggregate: Aggregate) -> list[Sample]:
        """One result per interval of [start, end) (OPC UA ReadProcessed); BAD quality where there is no data."""
        if interval <= 0:
            raise ValueError("the processing interval must be positive")
        tag_id, info = self._tag(tag)
        if not info.numeric and aggregate not in (Aggregate.INTERPOLATIVE, Aggregate.COUNT):
            raise ValueError(f"aggregate {aggregate.value} needs a numeric tag; {tag} is a {info.type}")
        page = self.raw(tag, start, end, bounds=True)
        samples = page.samples
        after = page.after
        results: list[Sample] = []
        index = 0
        previous = page.before if page.before is not None else None
        count = max(1, math.ceil((end - start) / interval - 1e-9))
        for number in range(count):
            a = start + number * interval
            b = min(end, a + interval)
            inside: list[Sample] = []
            while index < len(samples) and samples[index].time < b:
                sample = samples[index]
                if sample.time < a:
                    previous = sample
                else:
                    inside.append(sample)
                index += 1
            following = samples[index] if index < len(samples) else after
            results.append(self._aggregate(aggregate, info, a, b, previous, inside, following))
            if inside:
                previous = inside[-1]
        return results

    def at_time(self, tag: str, times: Iterable[float]) -> list[Sample | None]:
        """The value at each time (OPC UA ReadAtTime): stored, or interpolated; None where there is none before."""
        tag_id, info = self._tag(tag)
        results: list[Sample | None] = []
        for when in times:
            before = self._edge(tag_id, info, when, before=True, inclusive=True, good_only=True)
            after = None if info.stepped or (before is not None and before.time == when) else self._edge(tag_id, info, when, before=False, good_only=True)
            results.append(interpolate(before, after, when, stepped=info.stepped))
        return results

    # -- internals ------------------------------------------------------------------------

    def _aggregate(self, aggregate: Aggregate, info: TagInfo, a: float, b: float, previous: Sample | None,
                   inside: Sequence[Sample], following: Sample | None) -> Sample:
        stepped = info.stepped
        if aggregate is Aggregate.COUNT:
            return Sample(a, len(inside))
        if aggregate is Aggregate.INTERPOLATIVE:
            if inside and inside[0].time == a:
                return inside[0]
            nxt = inside[0] if inside else following
            return interpolate(previous, nxt, a, stepped=stepped) or Sample(a, None, Quality.BAD)
        if aggregate is Aggregate.AVERAGE:
            first = inside[0] if inside and inside[0].time == a else interpolate(previous, inside[0] if inside else following, a, stepped=stepped)
            rest = [s for s in inside if s.time > a]
            last_known = rest[-1] if rest else first
            stop = interpolate(last_known, following, b, stepped=stepped) if following is not None and last_known is not None else None
            return time_weighted_average(first, rest, stop, b, stepped=stepped)
        largest = aggregate in (Aggregate.MAXIMUM, Aggregate.MAXIMUM_ACTUAL_TIME)
        found = extreme(inside, largest=largest)
        if found is None:
            return Sample(a, None, Quality.BAD)
        actual = aggregate in (Aggregate.MINIMUM_ACTUAL_TIME, Aggregate.MAXIMUM_ACTUAL_TIME)
        return Sample(found.time if actual else a, found.value, found.quality)

    def _numeric_rows(self, tag_id: int, start: float, end: float) -> list[tuple[float, float]]:
        rows: list[tuple[float, float]] = []
        if end <= start:
            return rows
        for table in self._partitions(start, end):
            rows += self._query(f"SELECT time, value FROM {table} WHERE tag = ? AND time >= ? AND time < ? AND quality < 2 AND value IS NOT NULL ORDER BY time",
                                (tag_id, start, end))
        return rows

    def _edge(self, tag_id: int, info: TagInfo, when: float, *, before: bool, inclusive: bool = False, good_only: bool = False) -> Sample | None:
        """The last sample before `when` (or at it, if inclusive), or the first at or after it."""
        relation = ("<=" if inclusive else "<") if before else ">="
        order = "DESC" if before else "ASC"
        quality = " AND quality < 2" if good_only else ""
        bound = "start <= ?" if before else "stop > ?"
        partitions = self._query(f"SELECT name FROM history_partitions WHERE {bound} ORDER BY start {order}",
                                 (when if math.isfinite(when) else (1e300 if when > 0 else -1e300),))
        for (table,) in partitions:
            rows = self._query(f"SELECT time, value, text, quality FROM {table} WHERE tag = ? AND time {relation} ?{quality} "
                               f"ORDER BY time {order}, quality {order}, value {order}, text {order} LIMIT 1",
                               (tag_id, when if math.isfinite(when) else (1e300 if when > 0 else -1e300)))
            if rows:
                return _sample(rows[0], info)
        return None

    def _tag(self, tag: str) -> tuple[int, TagInfo]:
        rows = self._query("SELECT id, type, unit, stepped FROM history_tags WHERE plant = ? AND name = ?", (self.plant, tag))
        if not rows:
            raise UnknownTag(f"no history of {tag} (plant {self.plant}) in {self.database.describe()}")
        tag_id, kind, unit, stepped = rows[0]
        return int(tag_id), TagInfo(tag, kind, unit, bool(stepped))

    def _partitions(self, start: float, end: float) -> list[str]:
        rows = self._query("SELECT name FROM history_partitions WHERE stop > ? AND start < ? ORDER BY start", (start, end))
        return [name for (name,) in rows]

    def _query(self, sql: str, parameters: Sequence[Any]) -> list[tuple[Any, ...]]:
        with self._lock:
            if self._connection is None:
                if not self.database.exists():
                    raise StorageError(f"no history store at {self.database.describe()}")
                self._connection = self.database.connect(readonly=True)
            cursor = self._connection.cursor()
            try:
                cursor.execute(self.database.sql(sql), tuple(parameters))
                rows = cursor.fetchall()
            except Exception as error:
                if self.database.postgresql:
                    self._connection.rollback()
                if "history_" in str(error) and ("no such table" in str(error) or "does not exist" in str(error)):
                    raise StorageError(f"{self.database.describe()} holds no history (no history tables)") from error
                raise
            if self.database.postgresql:
                self._connection.rollback()  # end the read transaction: no snapshot held between calls
            return rows


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
