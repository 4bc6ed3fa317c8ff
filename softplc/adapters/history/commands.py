"""The historian's commands: how other adapters (OPC UA HistoryRead, the HMI's trends) read history.

Registered by the running historian (`HistoryRecorder.start`) on `plant.commands`, all VIEW
(any role), not audited; each does its store work off the event loop (`clock.run_blocking`) and
returns plain data (dicts, lists, numbers, strings, None; built in the worker thread too) — what `softplc.adapters.opcua.commands` sends
as JSON to remote callers too. Times are Unix seconds on the runtime clock (simulated under
--sim), like tag timestamps. A value is {"time", "value", "quality", "flags"}: quality "good" /
"uncertain" / "bad"; flags from Part 13 ("calculated", "interpolated", "partial", "multi_value",
"no_data", "sub_normal", "no_bound"). The arguments and results are listed in docs/history.md.

Values reach the store at the writer's next flush (`flush_period`, 1 s by default): a read sees
what was committed, not the last second still in memory.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Collection, Mapping
from typing import TYPE_CHECKING, Any

from softplc.adapters.history.aggregates import Aggregate, AggregateConfig
from softplc.adapters.history.queries import DEFAULT_PLOT_POINTS, HistoryReader, UnknownTag
from softplc.adapters.history.reads import (
    MAX_VALUES,
    InvalidContinuation,
    as_dict,
    read_at_time,
    read_processed,
    read_raw,
)
from softplc.adapters.history.store import TagInfo
from softplc.core.commands import CommandRefused, Permission

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

MAX_PLOT_POINTS = 10_000

_RANGE = {"tag": "tag name", "start": "Unix seconds (runtime clock); omitted: open", "end": "Unix seconds; omitted: open"}


def register_history_commands(plant: Plant, reader: HistoryReader, recorded: Mapping[str, TagInfo],
                              compressed: Collection[str] = ()) -> Callable[[], None]:
    """Register the `history.*` commands over `reader`; `recorded`: the tags this plant records (`compressed`: those
    with swinging-door compression). Returns an unregister."""
    run = plant.clock.run_blocking

    async def blocking(function: Callable[[], Any]) -> Any:
        try:
            return await run(function)
        except UnknownTag as error:
            raise CommandRefused(str(error)) from None
        except InvalidContinuation as error:
            raise CommandRefused(f"continuation: {error}") from None
        except ValueError as error:
            raise CommandRefused(str(error)) from None
        except Exception as error:  # StorageError, or the database driver's: the store is unreachable
            log.debug("history read failed", exc_info=True)
            raise CommandRefused(f"history is not readable now: {error}") from None

    def tags(arguments: Mapping[str, Any], origin: Any) -> list[dict[str, Any]]:
        # `compressed`: the archive is a straight-line approximation (trends draw it sloped); every other
        # tag's stored value holds until its next one, within its deadband (trends draw steps).
        return [{"tag": info.name, "type": info.type, "unit": info.unit, "interpolation": "stepped" if info.stepped else "sloped",
                 "compressed": info.name in compressed}
                for info in sorted(recorded.values(), key=lambda info: info.name)]

    def aggregates(arguments: Mapping[str, Any], origin: Any) -> list[str]:
        return [aggregate.value for aggregate in Aggregate]

    async def raw(arguments: Mapping[str, Any], origin: Any) -> dict[str, Any]:
        tag = _tag(arguments)
        token = _optional_text(arguments, "continuation")
        start, end = _time(arguments, "start"), _time(arguments, "end")
        limit, bounds = _count(arguments, "limit"), _flag(arguments, "bounds")
        return await blocking(lambda: _page(read_raw(reader, tag, start, end, limit=limit, bounds=bounds, token=token)))

    async def processed(arguments: Mapping[str, Any], origin: Any) -> dict[str, Any]:
        tag = _tag(arguments)
        token = _optional_text(arguments, "continuation")
        start, end = _required_time(arguments, "start", token), _required_time(arguments, "end", token)
        interval = _number(arguments, "interval", 0.0)
        aggregate = _aggregate(arguments, token)
        config = _config(arguments.get("config"))
        limit = _count(arguments, "limit")
        return await blocking(lambda: _page(read_processed(reader, tag, start, end, interval, aggregate, config=config,
                                                           limit=limit, token=token)))

    async def at_time(arguments: Mapping[str, Any], origin: Any) -> dict[str, Any]:
        tag = _tag(arguments)
        times = arguments.get("times")
        if not isinstance(times, (list, tuple)) or not all(_is_time(t) for t in times):
            raise CommandRefused("times: a list of Unix seconds")
        simple, config = _flag(arguments, "simple_bounds"), _config(arguments.get("config"))
        moments = [float(t) for t in times]
        return await blocking(lambda: {"samples": [as_dict(r) for r in read_at_time(reader, tag, moments, simple_bounds=simple, config=config)]})

    async def plot(arguments: Mapping[str, Any], origin: Any) -> dict[str, Any]:
        tag = _tag(arguments)
        start, end = _required_time(arguments, "start", None), _required_time(arguments, "end", None)
        points = _count(arguments, "max_points") or DEFAULT_PLOT_POINTS
        if not 2 <= points <= MAX_PLOT_POINTS:
            raise CommandRefused(f"max_points: 2 to {MAX_PLOT_POINTS}, not {points}")
        def plotted() -> dict[str, Any]:
            result = reader.plot(tag, start, end, points)
            return {"samples": [as_dict(s) for s in result.samples], "decimated": result.decimated, "bucket": result.bucket}

        return await blocking(plotted)

    raw_arguments = {**_RANGE, "limit": f"at most this many values (0: {MAX_VALUES}); more: a continuation",
                     "bounds": "true: add the bounding values", "continuation": "the previous page's continuation"}
    processed_arguments = {"tag": "tag name", "start": "Unix seconds", "end": "Unix seconds (before start: backwards)",
                           "interval": "seconds per interval (0: one interval)", "aggregate": "one of history.aggregates",
                           "config": "{treat_uncertain_as_bad, percent_data_bad, percent_data_good} (optional)",
                           "limit": f"at most this many intervals (0: {MAX_VALUES})", "continuation": "the previous page's continuation"}
    unregister = [
        plant.commands.register("history.tags", tags, permission=Permission.VIEW, description="list the tags with history"),
        plant.commands.register("history.aggregates", aggregates, permission=Permission.VIEW,
                                  description="list the aggregates of history.read_processed"),
        plant.commands.register("history.read_raw", raw, permission=Permission.VIEW, description="read raw history",
                                  arguments=raw_arguments),
        plant.commands.register("history.read_processed", processed, permission=Permission.VIEW,
                                  description="read aggregates of history per interval", arguments=processed_arguments),
        plant.commands.register("history.read_at_time", at_time, permission=Permission.VIEW, description="read history at given times",
                                  arguments={"tag": "tag name", "times": "list of Unix seconds",
                                             "simple_bounds": "true: Part 13 simple bounding values", "config": "as for read_processed"}),
        plant.commands.register("history.plot", plot, permission=Permission.VIEW, description="read history for a trend",
                                  arguments={"tag": "tag name", "start": "Unix seconds", "end": "Unix seconds",
                                             "max_points": f"at most this many points (default {DEFAULT_PLOT_POINTS})"}),
    ]

    def unregister_all() -> None:
        for undo in unregister:
            undo()

    return unregister_all


def _page(page: tuple[list[Any], str | None]) -> dict[str, Any]:
    """A page of results as plain data (built in the worker thread, not on the event loop)."""
    results, more = page
    return {"samples": [as_dict(r) for r in results], "continuation": more}


# -- argument checks: a clear refusal for each mistake -------------------------------------------


def _tag(arguments: Mapping[str, Any]) -> str:
    tag = arguments.get("tag")
    if not isinstance(tag, str) or not tag:
        raise CommandRefused("tag: a tag name is needed")
    return tag


def _is_time(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _time(arguments: Mapping[str, Any], key: str) -> float | None:
    value = arguments.get(key)
    if value is None:
        return None
    if not _is_time(value):
        raise CommandRefused(f"{key}: Unix seconds (a number), not {value!r}")
    return float(value)


def _required_time(arguments: Mapping[str, Any], key: str, token: str | None) -> float:
    value = _time(arguments, key)
    if value is None:
        if token is not None:
            return 0.0  # the continuation holds the request
        raise CommandRefused(f"{key}: Unix seconds are needed")
    return value


def _number(arguments: Mapping[str, Any], key: str, default: float) -> float:
    value = arguments.get(key, default)
    if not _is_time(value) or value < 0:
        raise CommandRefused(f"{key}: a number of seconds, zero or more, not {value!r}")
    return float(value)


def _count(arguments: Mapping[str, Any], key: str) -> int:
    value = arguments.get(key, 0) or 0
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise CommandRefused(f"{key}: a whole number, zero or more, not {value!r}")
    return value


def _flag(arguments: Mapping[str, Any], key: str) -> bool:
    value = arguments.get(key, False)
    if not isinstance(value, bool):
        raise CommandRefused(f"{key}: true or false, not {value!r}")
    return value


def _optional_text(arguments: Mapping[str, Any], key: str) -> str | None:
    value = arguments.get(key)
    if value is not None and not isinstance(value, str):
        raise CommandRefused(f"{key}: the text a previous read returned")
    return value or None


def _aggregate(arguments: Mapping[str, Any], token: str | None) -> Aggregate:
    name = arguments.get("aggregate")
    if name is None and token is not None:
        return Aggregate.AVERAGE  # the continuation holds the request
    try:
        return Aggregate(name)
    except ValueError:
        raise CommandRefused(f"aggregate: one of {', '.join(a.value for a in Aggregate)}, not {name!r}") from None


def _config(value: Any) -> AggregateConfig:
    if value is None:
        return AggregateConfig()
    if not isinstance(value, Mapping):
        raise CommandRefused("config: {treat_uncertain_as_bad, percent_data_bad, percent_data_good}")
    unknown = set(value) - {"treat_uncertain_as_bad", "percent_data_bad", "percent_data_good"}
    if unknown:
        raise CommandRefused(f"config: unknown key {sorted(unknown)[0]!r}")
    treat = value.get("treat_uncertain_as_bad", True)
    if not isinstance(treat, bool):
        raise CommandRefused("config: treat_uncertain_as_bad is true or false")
    try:
        return AggregateConfig(treat, value.get("percent_data_bad", 100), value.get("percent_data_good", 100))
    except ValueError as error:
        raise CommandRefused(f"config: {error}") from None
