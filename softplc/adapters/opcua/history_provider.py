"""The OPC UA server's HistoryProvider over the historian's commands (`history.*` on `plant.commands`).

The OPC UA adapter never imports the historian: it asks the command registry. `CommandHistory.
connect(commands)` is None when no historian runs; otherwise it has learnt, once, which tags
have history and which aggregates are offered (the historian starts before the OPC UA server,
see softplc/app/adapters.py, so the address space can say Historizing). Each read is one command
call; the historian's results (quality + Part 13 flags) become exact OPC UA StatusCodes here.

The reads are called with an internal origin: the `history.*` commands are VIEW ones, which every
role may call, and asyncua hands the history manager no session to take a role from.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from asyncua import ua

from softplc.adapters.opcua.history import HistoryPage, HistoryUnavailable, Sample
from softplc.core.commands import CommandRefused, Commands
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality

ORIGIN = Origin("opcua", "history", role=None)

# Part 13 names of the historian's aggregates (softplc.adapters.history.aggregates.Aggregate values).
PART13_NAMES = {
    "interpolative": "Interpolative", "average": "Average", "time_average": "TimeAverage2", "minimum": "Minimum",
    "maximum": "Maximum", "minimum_actual_time": "MinimumActualTime", "maximum_actual_time": "MaximumActualTime",
    "count": "Count",
}
_TEXT_AGGREGATES = frozenset({"Interpolative", "Count"})  # the ones a string tag has
_BASE = {"good": ua.StatusCodes.Good, "uncertain": ua.StatusCodes.Uncertain, "bad": ua.StatusCodes.Bad}
_INFO_BITS = {"calculated": 0x1, "interpolated": 0x2, "partial": 0x4, "multi_value": 0x10}
_INFO_TYPE_DATA_VALUE = 0x400  # StatusCode InfoType: the low bits are Part 13's historian bits


class CommandHistory:
    """A HistoryProvider that reads through `history.read_raw`, `read_processed` and `read_at_time`."""

    def __init__(self, commands: Commands, tags: Mapping[str, Mapping[str, Any]], aggregates: Mapping[str, str]) -> None:
        self.commands = commands
        self.tags = dict(tags)
        self._names = dict(aggregates)  # Part 13 name → historian name
        self.aggregates = frozenset(self._names)

    @classmethod
    async def connect(cls, commands: Commands) -> CommandHistory | None:
        """The provider of the running historian, or None when there is none."""
        if "history.tags" not in commands:
            return None
        tags = await commands.call("history.tags", {}, ORIGIN)
        offered = await commands.call("history.aggregates", {}, ORIGIN)
        names = {PART13_NAMES[name]: name for name in offered if name in PART13_NAMES}
        return cls(commands, {entry["tag"]: entry for entry in tags}, names)

    def historized(self, tag: str) -> bool:
        return tag in self.tags

    def supports(self, tag: str, aggregate: str) -> bool:
        return self.tags[tag].get("type") != "string" or aggregate in _TEXT_AGGREGATES

    async def read_raw(self, tag: str, start: float | None, end: float | None, limit: int, resume: bytes | None,
                       bounds: bool = False) -> HistoryPage:
        arguments = {"tag": tag, "start": start, "end": end, "limit": limit, "bounds": bounds}
        return await self._page("history.read_raw", arguments, resume)

    async def read_processed(self, tag: str, start: float | None, end: float | None, interval: float, aggregate: str,
                             config: tuple[bool, int, int] | None, limit: int, resume: bytes | None) -> HistoryPage:
        arguments: dict[str, Any] = {"tag": tag, "start": start, "end": end, "interval": interval,
                                     "aggregate": self._names[aggregate], "limit": limit}
        if config is not None:
            arguments["config"] = dict(zip(("treat_uncertain_as_bad", "percent_data_bad", "percent_data_good"), config))
        return await self._page("history.read_processed", arguments, resume)

    async def read_at_time(self, tag: str, times: Sequence[float], simple_bounds: bool) -> list[Sample]:
        result = await self._call("history.read_at_time", {"tag": tag, "times": list(times), "simple_bounds": simple_bounds}, None)
        return [_sample(entry) for entry in result["samples"]]

    async def _page(self, name: str, arguments: dict[str, Any], resume: bytes | None) -> HistoryPage:
        if resume is not None:
            try:
                arguments["continuation"] = resume.decode("ascii")
            except UnicodeDecodeError:
                raise ValueError("not a continuation of this historian") from None
        result = await self._call(name, arguments, resume)
        more = result.get("continuation")
        return HistoryPage([_sample(entry) for entry in result["samples"]], more.encode("ascii") if more else None)

    async def _call(self, name: str, arguments: dict[str, Any], resume: bytes | None) -> Any:
        try:
            return await self.commands.call(name, arguments, ORIGIN)
        except CommandRefused as refused:
            # With a continuation point the request's details are ignored: what was refused is the point.
            if resume is not None:
                raise ValueError(str(refused)) from None
            raise HistoryUnavailable(str(refused)) from None


_QUALITIES = {quality.value: quality for quality in Quality}
_statuses: dict[tuple[str, tuple[str, ...]], int] = {}


def _sample(entry: Mapping[str, Any]) -> Sample:
    key = (entry["quality"], tuple(entry.get("flags", ())))
    status = _statuses.get(key)
    if status is None:
        status = _statuses[key] = status_code(*key)
    return Sample(entry["time"], entry["value"], _QUALITIES[key[0]], status)


def status_code(quality: str, flags: Sequence[str]) -> int:
    """The OPC UA StatusCode of a historian value: its quality, refined by its Part 13 flags."""
    if "no_bound" in flags:
        return ua.StatusCodes.BadBoundNotFound
    if "no_data" in flags:
        return ua.StatusCodes.BadNoData
    if quality == "uncertain" and "sub_normal" in flags:
        code = ua.StatusCodes.UncertainDataSubNormal
    else:
        code = _BASE[quality]
    bits = sum(bit for name, bit in _INFO_BITS.items() if name in flags)
    return code | _INFO_TYPE_DATA_VALUE | bits if bits else code
