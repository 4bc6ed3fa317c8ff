"""The history store and its queries, on SQLite and on a real PostgreSQL server (same tests)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import pytest

from softplc.adapters.history.aggregates import Sample
from softplc.adapters.history.columns import QUALITY_CODES
from softplc.adapters.history.queries import Continuation, HistoryReader, UnknownTag
from softplc.adapters.history.store import HistorySink, TagInfo
from softplc.core.tags import Quality
from softplc.storage import BatchWriter, Database, StorageSettings

T0 = 1_767_225_600.0  # 2026-01-01T00:00:00Z, a partition boundary
GOOD, BAD = Quality.GOOD, Quality.BAD
TAGS = [TagInfo("level", "float64", "%"), TagInfo("count", "int32", stepped=True), TagInfo("state", "string", stepped=True),
        TagInfo("on", "bool", stepped=True)]


class Store:
    """A writer with the history sink, and a reader, on one backend."""

    def __init__(self, settings: StorageSettings, *, plant: str = "plant", partition: float = 86400.0, retention: float | None = None) -> None:
        self.database = Database(settings)
        self.sink = HistorySink(plant, TAGS, partition=partition, retention=retention)
        self.writer = BatchWriter(self.database, flush_period=0.05)
        self.writer.register(self.sink)
        assert self.writer.start() is None
        self.reader = HistoryReader(self.database, plant)

    def write(self, rows: Iterable[tuple[str, float, Any, Quality]], *, maintain: bool = False) -> None:
        self.writer.put("history", [(name, when, value, QUALITY_CODES[quality]) for name, when, value, quality in rows])
        assert self.writer.flush(timeout=60, maintain=maintain)

    def close(self) -> None:
        self.writer.stop()
        self.reader.close()

    def tables(self) -> set[str]:
        connection = self.database.connect(readonly=True)
        try:
            cursor = connection.cursor()
            if self.database.postgresql:
                cursor.execute("SELECT tablename FROM pg_tables WHERE schemaname = current_schema()")
            else:
                cursor.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
            return {row[0] for row in cursor.fetchall()}
        finally:
            connection.close()


@pytest.fixture
def store(storage_settings: StorageSettings):
    opened = Store(storage_settings)
    yield opened
    opened.close()


def values(samples: list[Sample]) -> list[tuple[float, Any]]:
    return [(s.time - T0, s.value) for s in samples]


def test_raw_reads_in_pages_with_continuation_points_and_bounds(store: Store) -> None:
    rows = [("level", T0 + t, float(t), GOOD) for t in range(10)] + [("level", T0 + 4, 40.0, GOOD)]  # two samples at t=4
    store.write(rows)
    everything = store.reader.raw("level", T0, T0 + 10).samples
    assert [s.time - T0 for s in everything] == [0, 1, 2, 3, 4, 4, 5, 6, 7, 8, 9]
    pages, continuation = [], None
    while True:
        page = store.reader.raw("level", T0, T0 + 10, limit=3, continuation=continuation)
        pages.append(page.samples)
        continuation = page.continuation
        if continuation is None:
            break
    assert [len(p) for p in pages] == [3, 3, 3, 2]
    assert [s for p in pages for s in p] == everything  # each sample exactly once, even the tie at t=4
    assert pages[1][-1].time - T0 == 4  # a page may end inside a tie: the continuation skips what was read
    page = store.reader.raw("level", T0 + 2.5, T0 + 5, bounds=True)
    assert values(page.samples) == [(3, 3.0), (4, 4.0), (4, 40.0)] or values(page.samples) == [(3, 3.0), (4, 40.0), (4, 4.0)]
    assert (page.before.time - T0, page.before.value) == (2, 2.0)
    assert (page.after.time - T0, page.after.value) == (5, 5.0)
    assert store.reader.raw("level", T0 + 20, T0 + 30, bounds=True).after is None
    with pytest.raises(UnknownTag):
        store.reader.raw("missing", T0, T0 + 1)
    assert Continuation(T0, 0) == (T0, 0)


def test_values_of_every_type_and_quality_come_back_as_stored(store: Store) -> None:
    store.write([("count", T0, 7, GOOD), ("state", T0, "moving", GOOD), ("on", T0, True, GOOD), ("level", T0, math.nan, Quality.UNCERTAIN),
                 ("state", T0 + 1, "blocked ü", BAD)])
    assert store.reader.raw("count", T0, T0 + 1).samples == [Sample(T0, 7, GOOD)]
    assert store.reader.raw("state", T0, T0 + 2).samples == [Sample(T0, "moving", GOOD), Sample(T0 + 1, "blocked ü", BAD)]
    assert store.reader.raw("on", T0, T0 + 1).samples == [Sample(T0, True, GOOD)]
    nan = store.reader.raw("level", T0, T0 + 1).samples[0]
    assert math.isnan(nan.value) and nan.quality is Quality.UNCERTAIN
    assert set(store.reader.historized()) == {"level", "count", "state", "on"}
    assert store.reader.historized()["count"].stepped


def test_retention_drops_whole_partitions(storage_settings: StorageSettings) -> None:
    store = Store(storage_settings, partition=3600.0, retention=2 * 3600.0)
    try:
        store.write([("level", T0 + hour * 3600 + 10, float(hour), GOOD) for hour in range(4)])  # four hourly partitions
        assert {"history_20260101_000000", "history_20260101_030000", "history_20260101_030000_m1"} <= store.tables()
        store.write([("level", T0 + 4 * 3600 + 10, 4.0, GOOD)], maintain=True)  # now 04:00:10: keep 02:00:10 onwards
        tables = store.tables()
        assert "history_20260101_000000" not in tables and "history_20260101_000000_h1" not in tables
        assert "history_20260101_010000" not in tables  # it ended at 02:00, before the cutoff
        assert "history_20260101_020000" in tables
        assert values(store.reader.raw("level", T0, T0 + 5 * 3600).samples) == [(2 * 3600 + 10, 2.0), (3 * 3600 + 10, 3.0), (4 * 3600 + 10, 4.0)]
    finally:
        store.close()


def test_a_day_is_plotted_in_at_most_n_points_and_no_spike_vanishes(store: Store) -> None:
    day = [("level", T0 + t, 50.0 + math.sin(t / 600.0), GOOD) for t in range(86400)]
    day[40_000] = ("level", T0 + 40_000, 99.0, GOOD)  # a one-second spike
    day[40_030] = ("level", T0 + 40_030, -5.0, GOOD)  # and a dip
    day[86_395] = ("level", T0 + 86_395, 120.0, GOOD)  # a spike in the last, partial minute cell of the range
    store.write(day)
    plot = store.reader.plot("level", T0, T0 + 86_399.5, max_points=2000)
    assert plot.decimated and 0 < len(plot.samples) <= 2000
    assert (T0 + 40_000, 99.0) in [(s.time, s.value) for s in plot.samples]
    assert (T0 + 40_030, -5.0) in [(s.time, s.value) for s in plot.samples]
    assert (T0 + 86_395, 120.0) in [(s.time, s.value) for s in plot.samples]
    assert [s.time for s in plot.samples] == sorted(s.time for s in plot.samples)
    # A range starting mid-minute (edge cells read raw) still holds the spike; a short one is raw.
    short = store.reader.plot("level", T0 + 39_990.5, T0 + 40_100.5, max_points=20)
    assert short.decimated and len(short.samples) <= 20 and 99.0 in [s.value for s in short.samples]
    assert not store.reader.plot("level", T0 + 100, T0 + 110, max_points=20).decimated
    month = store.reader.plot("level", T0 - 29 * 86400, T0 + 86400, max_points=500)
    assert len(month.samples) <= 500 and {99.0, -5.0, 120.0} <= {s.value for s in month.samples}


def test_a_decimated_plot_keeps_its_gaps(store: Store) -> None:
    rows = [("level", T0 + t, 50.0, GOOD) for t in range(30_000)]
    rows.append(("level", T0 + 30_000, math.nan, BAD))  # the end of a recording: nothing until the next start
    rows += [("level", T0 + t, 60.0, GOOD) for t in range(33_600, 86_400)]
    store.write(rows)
    # A day (the cells), a range read raw and decimated, and one that fits undecimated: the gap is in each.
    for start, end, points in ((T0, T0 + 86_400, 500), (T0 + 29_950, T0 + 30_050, 40), (T0 + 29_990, T0 + 30_010, 40)):
        plot = store.reader.plot("level", start, end, max_points=points)
        assert plot.decimated == (points == 500 or end - start == 100)
        gaps = [sample for sample in plot.samples if sample.quality is BAD]
        assert [sample.time for sample in gaps] == [T0 + 30_000] and math.isnan(gaps[0].value)
        assert [sample.time for sample in plot.samples] == sorted(sample.time for sample in plot.samples)
        assert len(plot.samples) <= points


def test_two_plants_share_one_store(storage_settings: StorageSettings) -> None:
    first = Store(storage_settings, plant="north")
    second = Store(storage_settings, plant="south")
    try:
        first.write([("level", T0, 1.0, GOOD)])
        second.write([("level", T0, 2.0, GOOD)])
        assert first.reader.raw("level", T0, T0 + 1).samples[0].value == 1.0
        assert second.reader.raw("level", T0, T0 + 1).samples[0].value == 2.0
        assert first.reader.plants() == ["north", "south"]
    finally:
        first.close()
        second.close()


def reference_cells(rows: list[tuple[str, float, Any, Quality]], width: float) -> dict[tuple[str, float], tuple[int, float, float, float, float]]:
    """Per (tag, cell): count, least value and its time, greatest and its time (the earliest on ties) — one sample at a time."""
    cells: dict[tuple[str, float], list[float]] = {}
    for name, when, value, quality in rows:
        if quality is BAD or isinstance(value, str) or value != value:
            continue
        key = (name, when - when % width)
        cell = cells.get(key)
        if cell is None:
            cells[key] = [1, float(value), when, float(value), when]
            continue
        cell[0] += 1
        if value < cell[1]:
            cell[1], cell[2] = float(value), when
        if value > cell[3]:
            cell[3], cell[4] = float(value), when
    return {key: tuple(cell) for key, cell in cells.items()}  # type: ignore[misc]


def stored_cells(store: Store, suffix: str) -> dict[tuple[str, float], tuple[int, float, float, float, float]]:
    connection = store.database.connect(readonly=True)
    try:
        names = dict(connection.execute("SELECT id, name FROM history_tags").fetchall())
        found = {}
        for (table,) in connection.execute("SELECT name FROM history_partitions").fetchall():
            for tag, cell, count, vmin, tmin, vmax, tmax in connection.execute(f"SELECT tag, cell, count, vmin, tmin, vmax, tmax FROM {table}_{suffix}"):
                found[(names[tag], cell)] = (count, vmin, tmin, vmax, tmax)
        return found
    finally:
        connection.close()


def test_samples_and_min_max_cells_of_many_batches_are_those_computed_one_sample_at_a_time(storage_settings: StorageSettings) -> None:
    import random

    generator = random.Random(16)
    store = Store(storage_settings, partition=3600.0)
    try:
        every: list[tuple[str, float, Any, Quality]] = []
        when = T0 - 1800.0  # across a partition boundary (hourly partitions) and many cells
        for _batch in range(6):
            rows = []
            for _ in range(3000):
                when += generator.choice([0.0, 0.25, 1.0, 7.0])  # ties on one instant too
                name = generator.choice(["level", "count", "on", "state"])
                quality = generator.choice([GOOD, GOOD, GOOD, Quality.UNCERTAIN, BAD])
                value: Any = {"level": generator.choice([1.5, 2.5, math.nan, generator.uniform(-5, 5)]),
                              "count": generator.randint(-3, 3), "on": generator.random() < 0.5,
                              "state": generator.choice(["idle", "busy"])}[name]
                rows.append((name, when, value, quality))
            store.write(rows)
            every += rows
        for suffix, width in (("s10", 10.0), ("m1", 60.0), ("h1", 3600.0)):
            expected = reference_cells(every, width)
            assert stored_cells(store, suffix) == expected, suffix
        for tag in ("state", "level", "count", "on"):
            stored = store.reader.raw(tag, T0 - 1800, when + 1).samples
            expected = [(t, "nan" if value != value else value, quality) for name, t, value, quality in every if name == tag]
            assert sorted(((s.time, "nan" if s.value != s.value else s.value, s.quality) for s in stored), key=repr) == sorted(expected, key=repr), tag
    finally:
        store.close()
