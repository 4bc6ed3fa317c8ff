"""History reads as OPC UA Part 11 defines them, page by page, with stateless continuation tokens.

Blocking functions over a `HistoryReader` (the `history.read_*` commands run them off the event
loop). Each returns results and, when more remain, a continuation token: an opaque string that
holds the whole request, so the next page needs only the token (Part 11 §6.3: with a
continuation point the request's details are ignored). A token is checked like any other input:
`InvalidContinuation` when it is not one of ours.

Raw reads (Part 11 §6.5.3, §4.4): start included, end excluded, in either direction (start > end,
or only an end, reads backwards); a bound left open reads to that end of the history. With
`bounds`, the bounding values come first and last: the value at start (or the nearest one outside
the range), the value at or beyond end; a bound that does not exist is a BAD value with flag
NO_BOUND at the requested time (OPC UA Bad_BoundNotFound). Bounds count towards the limit.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Sequence
from typing import Any

from softplc.adapters.history.aggregates import Aggregate, AggregateConfig, Flags, Result, Sample, interval_count
from softplc.adapters.history.queries import Continuation, HistoryReader
from softplc.core.tags import Quality

# Values per tag per call (OPC UA MaxReturnDataValues): more come with a continuation. Kept small
# because the caller's side (building the reply, asyncua encoding it) runs on the scan's event
# loop: ~15 ms for 1,000 values on this machine, ten times that for 10,000.
MAX_VALUES = 1_000
_PREFIX = "h1."
_MAX_TOKEN = 2048


class InvalidContinuation(ValueError):
    """A continuation token this historian did not give (or for another tag)."""


# -- raw --------------------------------------------------------------------------------------


def read_raw(reader: HistoryReader, tag: str, start: float | None, end: float | None, *, limit: int = 0,
             bounds: bool = False, token: str | None = None) -> tuple[list[Result], str | None]:
    """One page of raw values (see the module docstring); `limit` 0 (or above MAX_VALUES) means MAX_VALUES."""
    if token is not None:
        state = _decode(token, "raw", tag)
        start, end, limit, bounds = state["s"], state["e"], state["n"], state["b"]
        reverse, phase = state["r"], state["p"]
        position = Continuation(*state["c"]) if state["c"] is not None else None
    else:
        reverse = (start is None and end is not None) or (start is not None and end is not None and start > end)
        if start is None and end is not None:
            start, end = end, None  # only an end: read backwards from it, it is where the read starts
        phase, position = 0, None
    room = limit if 0 < limit <= MAX_VALUES else MAX_VALUES
    low = start if start is not None else (math.inf if reverse else -math.inf)
    high = end if end is not None else (-math.inf if reverse else math.inf)
    if start is not None and end is not None and start == end:
        high = math.nextafter(start, math.inf)  # the same instant twice: the values at that instant (time flows forward)
    results: list[Result] = []

    def more(next_phase: int, at: Continuation | None) -> tuple[list[Result], str]:
        state = {"k": "raw", "t": tag, "s": start, "e": end, "n": limit, "b": bounds, "r": reverse, "p": next_phase,
                 "c": list(at) if at is not None else None}
        return results, _encode(state)

    if phase == 0:
        if bounds and start is not None:
            step = -math.inf if reverse else math.inf
            if not reader.raw(tag, start, math.nextafter(start, step), limit=1, reverse=reverse).samples:
                edge = reader.raw(tag, start, start, bounds=True, reverse=reverse).before
                results.append(_raw(edge) if edge is not None else _no_bound(start))
        phase = 1
    if phase == 1:
        if len(results) >= room:
            return more(1, None)
        page = reader.raw(tag, low, high, limit=room - len(results), continuation=position, reverse=reverse)
        results.extend(_raw(sample) for sample in page.samples)
        if page.continuation is not None:
            return more(1, page.continuation)
        phase = 2
    if bounds and end is not None and end != start:
        if len(results) >= room:
            return more(2, None)
        edge = reader.raw(tag, end, end, bounds=True, reverse=reverse).after
        results.append(_raw(edge) if edge is not None else _no_bound(end))
    return results, None


# -- processed and at time --------------------------------------------------------------------


def read_processed(reader: HistoryReader, tag: str, start: float, end: float, interval: float, aggregate: Aggregate, *,
                   config: AggregateConfig, limit: int = 0, token: str | None = None) -> tuple[list[Result], str | None]:
    """One page of processed values: one per interval, at most `limit` (0: MAX_VALUES) intervals per call."""
    offset = 0
    if token is not None:
        state = _decode(token, "processed", tag)
        start, end, interval, limit, offset = state["s"], state["e"], state["i"], state["n"], state["o"]
        try:
            aggregate = Aggregate(state["a"])
            config = AggregateConfig(*state["cfg"])
        except (TypeError, ValueError):
            raise InvalidContinuation("not a continuation of this historian") from None
    total = interval_count(start, end, interval)
    room = limit if 0 < limit <= MAX_VALUES else MAX_VALUES
    count = min(room, total - offset)
    results = reader.processed(tag, start, end, interval, aggregate, config=config, first=offset, count=count)
    if offset + count >= total:
        return results, None
    state = {"k": "processed", "t": tag, "s": start, "e": end, "i": interval, "a": aggregate.value, "n": limit,
             "o": offset + count, "cfg": [config.treat_uncertain_as_bad, config.percent_data_bad, config.percent_data_good]}
    return results, _encode(state)


def read_at_time(reader: HistoryReader, tag: str, times: Sequence[float], *, simple_bounds: bool = False,
                 config: AggregateConfig | None = None) -> list[Result]:
    """The value at each time, in the order asked (ValueError for more than MAX_VALUES times)."""
    if len(times) > MAX_VALUES:
        raise ValueError(f"at most {MAX_VALUES} times per read, not {len(times)}")
    return reader.at_time(tag, times, simple_bounds=simple_bounds, config=config or AggregateConfig())


# -- results as plain data --------------------------------------------------------------------


_FLAG_NAMES = [(flag, str(flag.name).lower()) for flag in Flags if flag is not Flags.NONE]
_names_of: dict[int, tuple[str, ...]] = {}  # flags value → names (iterating an IntFlag is slow)


def as_dict(result: Result | Sample) -> dict[str, Any]:
    """A result as JSON-ready data: {"time", "value", "quality", "flags"} (NaN becomes None)."""
    value = result.value
    if value != value:  # NaN
        value = None
    flags = int(result.flags) if isinstance(result, Result) else 0
    names = _names_of.get(flags)
    if names is None:
        names = _names_of[flags] = tuple(name for flag, name in _FLAG_NAMES if flags & flag)
    return {"time": result.time, "value": value, "quality": result.quality.value, "flags": list(names)}


def _raw(sample: Sample) -> Result:
    return Result(sample.time, sample.value, sample.quality)


def _no_bound(when: float) -> Result:
    return Result(when, None, Quality.BAD, Flags.NO_BOUND)


def _encode(state: dict[str, Any]) -> str:
    text = json.dumps(state, separators=(",", ":"), allow_nan=False)
    return _PREFIX + base64.urlsafe_b64encode(text.encode()).decode().rstrip("=")


_KINDS: dict[str, dict[str, tuple[type, ...]]] = {
    "raw": {"s": (float, int, type(None)), "e": (float, int, type(None)), "n": (int,), "b": (bool,), "r": (bool,),
            "p": (int,), "c": (list, type(None))},
    "processed": {"s": (float, int), "e": (float, int), "i": (float, int), "a": (str,), "n": (int,), "o": (int,), "cfg": (list,)},
}


def _decode(token: str, kind: str, tag: str) -> dict[str, Any]:
    """The state in a token of `kind` for `tag`; InvalidContinuation for anything else."""
    try:
        if not isinstance(token, str) or len(token) > _MAX_TOKEN or not token.startswith(_PREFIX):
            raise ValueError
        body = token[len(_PREFIX):]
        state = json.loads(base64.urlsafe_b64decode(body + "=" * (-len(body) % 4)))
        if not isinstance(state, dict) or state.get("k") != kind or state.get("t") != tag:
            raise ValueError
        for key, types in _KINDS[kind].items():
            value = state.get(key, ...)
            if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
                raise ValueError
        position = state.get("c")
        if position is not None and not (len(position) == 2 and isinstance(position[0], (int, float))
                                         and isinstance(position[1], int) and position[1] >= 0):
            raise ValueError
        if state.get("o", 0) < 0 or state.get("p", 0) not in (0, 1, 2) or state["n"] < 0:
            raise ValueError
    except (ValueError, TypeError, UnicodeDecodeError):
        raise InvalidContinuation("not a continuation of this historian (or for another tag)") from None
    return state
