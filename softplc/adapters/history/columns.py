"""A batch of history rows as numpy columns, and their min/max cells: the writer's per-value work done in C.

The recorder queues rows `(tag name, time, value, quality code)` on the event loop (a tuple each:
the cheapest thing to build there; `QUALITY_CODES`: 0 good, 1 uncertain, 2 bad). The writer turns
a batch of them into columns with a handful of C calls (`to_columns`: no Python code runs per
value), sorts them by tag and time (SQLite then inserts into its (tag, time) index in runs: ~40 %
cheaper than interleaved), reduces them into the per-10 s, per-minute and per-hour min/max cells
with sorts instead of a dictionary per value (`Cells`), and hands the driver its parameters as
iterators over lists — or, for PostgreSQL, binary COPY data laid out by numpy (`copy_binary`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass
from itertools import repeat
from typing import Any

import numpy as np

from softplc.core.tags import Quality

QUALITY_CODES = {Quality.GOOD: 0, Quality.UNCERTAIN: 1, Quality.BAD: 2}
BAD = QUALITY_CODES[Quality.BAD]


@dataclass
class Columns:
    """Rows as columns: tag ids, times, numbers (NaN for text and NaN), quality codes; text by row position."""

    tags: np.ndarray  # int64
    times: np.ndarray  # float64
    numbers: np.ndarray  # float64
    codes: np.ndarray  # int8
    texts: dict[int, str]

    def __len__(self) -> int:
        return len(self.times)

    def sorted(self) -> Columns:
        """By tag, then time (the order of the store's index); rows of one instant keep their order."""
        order = np.lexsort((self.times, self.tags))
        texts = {}
        if self.texts:
            position = np.empty(len(order), dtype=np.int64)
            position[order] = np.arange(len(order))
            texts = {int(position[index]): text for index, text in self.texts.items()}
        return Columns(self.tags[order], self.times[order], self.numbers[order], self.codes[order], texts)

    def select(self, mask: np.ndarray) -> Columns:
        """The rows where `mask` holds."""
        texts = {}
        if self.texts:
            position = np.cumsum(mask) - 1
            texts = {int(position[index]): text for index, text in self.texts.items() if mask[index]}
        return Columns(self.tags[mask], self.times[mask], self.numbers[mask], self.codes[mask], texts)

    def parameters(self) -> Iterator[tuple[Any, ...]]:
        """(tag, time, value, text, quality) per row for the driver — NULL for text and NaN values."""
        numbers = self.numbers
        values = numbers.tolist()
        for index in np.flatnonzero(numbers != numbers).tolist():  # NaN (and text): NULL, as SQLite would store NaN anyway
            values[index] = None
        texts: list[Any] = [None] * len(values)
        for index, text in self.texts.items():
            texts[index] = text
        return zip(self.tags.tolist(), self.times.tolist(), values, texts, self.codes.tolist())


# PostgreSQL's binary COPY (https://www.postgresql.org/docs/current/sql-copy.html#id-1.9.3.55.9.4): a
# signature, flags and header extension length, then per row the field count and (length, bytes) per
# field, big-endian, length -1 for NULL; -1 ends the data. A row of plain numbers has a fixed size, so
# numpy lays out a whole part at once: (tag int4, time float8, value float8, text NULL, quality int2).
COPY_HEADER = b"PGCOPY\n\xff\r\n\x00" + (0).to_bytes(4, "big") + (0).to_bytes(4, "big")
COPY_TRAILER = (-1).to_bytes(2, "big", signed=True)
_NUMBER_ROW = np.dtype([("fields", ">i2"), ("tag_length", ">i4"), ("tag", ">i4"), ("time_length", ">i4"), ("time", ">f8"),
                        ("value_length", ">i4"), ("value", ">f8"), ("text_length", ">i4"), ("quality_length", ">i4"),
                        ("quality", ">i2")])


def copy_binary(samples: Columns) -> Iterator[bytes]:
    """The samples as PostgreSQL binary COPY data, header and trailer included."""
    yield COPY_HEADER
    numbers = samples.numbers
    plain = numbers == numbers  # not NaN: text rows are NaN too
    rows = np.zeros(len(samples), dtype=_NUMBER_ROW)
    rows["fields"], rows["tag_length"], rows["time_length"], rows["value_length"] = 5, 4, 8, 8
    rows["text_length"], rows["quality_length"] = -1, 2
    rows["tag"], rows["time"], rows["value"], rows["quality"] = samples.tags, samples.times, numbers, samples.codes
    if plain.all():
        yield rows.tobytes()
    else:
        first = 0
        for index in np.flatnonzero(~plain).tolist():  # rows with a variable size (NULL value, text) one by one
            yield rows[first:index].tobytes()
            yield _copy_row(int(samples.tags[index]), float(samples.times[index]), samples.texts.get(index), int(samples.codes[index]))
            first = index + 1
        yield rows[first:].tobytes()
    yield COPY_TRAILER


def _copy_row(tag: int, when: float, text: str | None, code: int) -> bytes:
    """A row whose value is NULL (text, or NaN), in binary COPY."""
    head = (5).to_bytes(2, "big") + (4).to_bytes(4, "big") + tag.to_bytes(4, "big", signed=True)
    head += (8).to_bytes(4, "big") + np.array(when, ">f8").tobytes() + (-1).to_bytes(4, "big", signed=True)
    body = (-1).to_bytes(4, "big", signed=True) if text is None else len(data := text.encode()).to_bytes(4, "big") + data
    return head + body + (2).to_bytes(4, "big") + code.to_bytes(2, "big", signed=True)


def to_columns(rows: Sequence[tuple[str, float, Any, int]], ids: Mapping[str, int], register: Callable[[Collection[str]], None]) -> Columns:
    """Columns of queued rows; `register(names)` adds the names `ids` lacks to it first."""
    count = len(rows)
    if not count:
        return Columns(np.empty(0, np.int64), np.empty(0), np.empty(0), np.empty(0, np.int8), {})
    names, times, values, codes = zip(*rows)
    unknown = set(names).difference(ids)
    if unknown:
        register(unknown)
    tags = np.fromiter(map(ids.__getitem__, names), np.int64, count)
    is_text = np.fromiter(map(isinstance, values, repeat(str)), np.bool_, count)
    texts: dict[int, str] = {}
    if is_text.any():
        positions = np.flatnonzero(is_text).tolist()
        texts = {index: values[index] for index in positions}
        objects = np.array(values, dtype=object)
        objects[positions] = math.nan
        numbers = objects.astype(np.float64)
    else:
        numbers = np.fromiter(values, np.float64, count)
    return Columns(tags, np.fromiter(times, np.float64, count), numbers, np.fromiter(codes, np.int8, count), texts)


@dataclass
class Cells:
    """Min/max cells: per (tag, cell start) the count of good numeric samples, the least and greatest with their times."""

    tags: np.ndarray
    cells: np.ndarray
    counts: np.ndarray
    minimum: np.ndarray
    minimum_time: np.ndarray
    maximum: np.ndarray
    maximum_time: np.ndarray

    @classmethod
    def of_samples(cls, columns: Columns, width: float) -> Cells:
        """The cells `width` seconds wide of the good numeric samples among `columns`."""
        good = (columns.codes != BAD) & (columns.numbers == columns.numbers)  # not bad, not NaN (nor text)
        times, numbers = columns.times[good], columns.numbers[good]
        return cls(columns.tags[good], times - np.remainder(times, width), np.ones(len(times), np.int64),
                   numbers, times, numbers, times).reduced()

    def coarser(self, width: float) -> Cells:
        """These cells merged into cells `width` seconds wide (a multiple of theirs)."""
        return Cells(self.tags, self.cells - np.remainder(self.cells, width), self.counts, self.minimum, self.minimum_time,
                     self.maximum, self.maximum_time).reduced()

    def reduced(self) -> Cells:
        """One cell per (tag, cell): counts added, the least value (the earliest on ties) and the greatest (the earliest on ties)."""
        if len(self.tags) == 0:
            return self
        lows = np.lexsort((self.minimum_time, self.minimum, self.cells, self.tags))
        highs = np.lexsort((self.maximum_time, -self.maximum, self.cells, self.tags))
        tags, cells = self.tags[lows], self.cells[lows]
        starts = np.flatnonzero(np.concatenate(([True], (tags[1:] != tags[:-1]) | (cells[1:] != cells[:-1]))))
        low, high = lows[starts], highs[starts]  # both orders group by (tag, cell) alike: the same group starts
        return Cells(tags[starts], cells[starts], np.add.reduceat(self.counts[lows], starts), self.minimum[low],
                     self.minimum_time[low], self.maximum[high], self.maximum_time[high])

    def within(self, start: float, stop: float) -> Cells:
        mask = (self.cells >= start) & (self.cells < stop)
        return Cells(*(column[mask] for column in self._columns()))

    def parameters(self) -> Iterator[tuple[Any, ...]]:
        """(tag, cell, count, vmin, tmin, vmax, tmax) per cell for the driver."""
        return zip(*(column.tolist() for column in self._columns()))

    def _columns(self) -> tuple[np.ndarray, ...]:
        return (self.tags, self.cells, self.counts, self.minimum, self.minimum_time, self.maximum, self.maximum_time)

    def __len__(self) -> int:
        return len(self.tags)
