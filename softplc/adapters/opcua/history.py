"""HistoryRead: what the OPC UA server answers, and the small interface a historian plugs into.

asyncua 2.1.0 (pinned) answers every HistoryRead with Good and no data — even for node ids that
do not exist — and logs a warning per call. `TagHistoryService` (installed as the server's
`history_manager`) answers per item instead, without logging (docs/opcua.md#history has the
table of statuses):

    raw (ReadRawModifiedDetails, IsReadModified false), with bounds and continuation points;
    processed (ReadProcessedDetails: the provider's Part 13 aggregates, AggregateConfiguration);
    at time (ReadAtTimeDetails, UseSimpleBounds);
    BadNodeIdUnknown, BadHistoryOperationUnsupported (a node without history, modified values,
    events, annotations), BadAggregateNotSupported, BadAggregateListMismatch,
    BadAggregateConfigurationRejected, BadInvalidArgument, BadIndexRangeInvalid,
    BadContinuationPointInvalid, BadResourceUnavailable (the historian cannot read now);
    for the request: BadNothingToDo, BadTooManyOperations, BadTimestampsToReturnInvalid,
    BadHistoryOperationInvalid.

## The provider interface (for a historian)

`OpcUaServer(settings, history=provider)`; without one, the server reads through the running
historian's commands (`history_provider.CommandHistory`). Times are epoch seconds on the
runtime clock (tag timestamps); None: not given (open).

    historized(tag) -> bool
        Asked once per tag when the address space is built: AccessLevel HistoryRead and
        Historizing = True.
    async read_raw(tag, start, end, limit, resume[, bounds=True]) -> HistoryPage
        At most `limit` raw samples from `start` towards `end` (Part 11 §6.5.3: backwards when
        start > end or only end is given), with the bounding values first and last when
        `bounds` is passed. `HistoryPage.resume`: an opaque bytes token when more remain; the
        server wraps it (with the tag name) into the client's continuation point and passes it
        back as `resume` (the token must hold the whole request: Part 11 ignores the details
        then). Unrecognised token: raise ValueError. Stateless: a released point needs no
        clean-up. The service passes bounds only when asked for.
    aggregates: Collection[str]                                  (optional, with the next three)
        Part 13 names of the aggregates offered ("Average", "Interpolative", ...).
    supports(tag, aggregate) -> bool
        Whether that aggregate applies to that tag (no Average of a string).
    async read_processed(tag, start, end, interval, aggregate, config, limit, resume) -> HistoryPage
        One sample per interval (seconds; 0: one interval); `config` None (the defaults) or
        (treat_uncertain_as_bad, percent_data_bad, percent_data_good).
    async read_at_time(tag, times, simple_bounds) -> list[Sample]

A `Sample` is (time, value, quality[, status]): `status`, when given, is the exact OPC UA
StatusCode (Bad_NoData, Uncertain_DataSubNormal, the Part 13 info bits...). A provider that
cannot read now (its store is unreachable) raises `HistoryUnavailable`. It is awaited on the
scan's event loop: file or database work belongs in a thread (or the clock's `run_blocking`).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, Protocol

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.server.history import HistoryManager

from softplc.core.tagdb import TagDatabase
from softplc.core.tags import Quality
from softplc.protocols.opcua_variants import STATUS_CODES, VARIANT_TYPES

log = logging.getLogger(__name__)

MAX_NODES_PER_HISTORY_READ = 1000
# Values per node per call; more come with a continuation point. Building and encoding a reply runs
# on the scan's event loop (~10 ms for 1,000 values here, ten times that for 10,000): clients page.
MAX_RETURN_DATA_VALUES = 1_000
_CONTINUATION_MAGIC = b"SPH1"
_EPOCH_MIN = datetime(1601, 1, 2, tzinfo=timezone.utc)  # before this a DateTime means "not given"
_DOUBLE_AGGREGATES = frozenset({"Average", "TimeAverage", "TimeAverage2", "Total", "Total2"})
_BAD = ua.StatusCodes


@dataclass(frozen=True)
class Sample:
    """One historical value of a tag (`status`: the exact StatusCode, when more than the quality)."""

    time: float  # epoch seconds, runtime clock (as tag timestamps)
    value: Any
    quality: Quality = Quality.GOOD
    status: int | None = None


@dataclass(frozen=True)
class HistoryPage:
    """Samples of one read, and where to resume when more remain (None: that was all)."""

    samples: Sequence[Sample]
    resume: bytes | None = None


class HistoryUnavailable(Exception):
    """The historian cannot read now (e.g. its database is unreachable)."""


class HistoryProvider(Protocol):
    """What a historian offers the OPC UA server (see the module docstring)."""

    def historized(self, tag: str) -> bool: ...

    async def read_raw(self, tag: str, start: float | None, end: float | None, limit: int, resume: bytes | None) -> HistoryPage: ...


class NoHistory:
    """The provider while there is no historian: no tag has history."""

    def historized(self, tag: str) -> bool:
        return False

    async def read_raw(self, tag: str, start: float | None, end: float | None, limit: int, resume: bytes | None) -> HistoryPage:
        return HistoryPage(())


class TagHistoryService(HistoryManager):
    """asyncua's history manager with HistoryRead answered per item from a HistoryProvider."""

    def __init__(self, iserver: Any, db: TagDatabase, namespace_index: int, provider: HistoryProvider,
                 run_blocking: Callable[..., Awaitable[Any]] | None = None) -> None:
        """`run_blocking(function)`: where to build the DataValues of a reply (the runtime clock's: off the loop)."""
        super().__init__(iserver)
        self.db = db
        self.ns = namespace_index
        self.provider = provider
        self._run_blocking = run_blocking

    async def read_history(self, params: ua.HistoryReadParameters) -> list[ua.HistoryReadResult]:
        items = params.NodesToRead or []
        if not items:
            raise ServiceError(_BAD.BadNothingToDo)
        if len(items) > MAX_NODES_PER_HISTORY_READ:
            raise ServiceError(_BAD.BadTooManyOperations)
        if params.TimestampsToReturn not in (ua.TimestampsToReturn.Source, ua.TimestampsToReturn.Server, ua.TimestampsToReturn.Both):
            raise ServiceError(_BAD.BadTimestampsToReturnInvalid)
        details = params.HistoryReadDetails
        if isinstance(details, ua.ReadRawModifiedDetails) and not details.IsReadModified:
            return [await self._item(item, params, lambda tag, resume: self._raw(tag, details, resume)) for item in items]
        if isinstance(details, ua.ReadProcessedDetails) and hasattr(self.provider, "read_processed"):
            aggregates = details.AggregateType or []
            if len(aggregates) != len(items):
                return [_status(_BAD.BadAggregateListMismatch) for _ in items]
            return [await self._item(item, params, lambda tag, resume, kind=kind: self._processed(tag, details, kind, resume))
                    for item, kind in zip(items, aggregates)]
        if isinstance(details, ua.ReadAtTimeDetails) and hasattr(self.provider, "read_at_time"):
            return [await self._item(item, params, lambda tag, resume: self._at_time(tag, details, resume)) for item in items]
        if isinstance(details, (ua.ReadRawModifiedDetails, ua.ReadProcessedDetails, ua.ReadAtTimeDetails,
                                ua.ReadEventDetails, ua.ReadAnnotationDataDetails)):
            return [await self._item(item, params, None) for item in items]
        raise ServiceError(_BAD.BadHistoryOperationInvalid)

    async def _item(self, item: ua.HistoryReadValueId, params: ua.HistoryReadParameters, read: Any) -> ua.HistoryReadResult:
        """Checks common to every kind of read, then `read(tag, resume)` → (samples, variant type, resume) or a status."""
        node_id = item.NodeId
        if node_id not in self.iserver.aspace:
            return _status(_BAD.BadNodeIdUnknown)
        tag = node_id.Identifier if node_id.NamespaceIndex == self.ns and isinstance(node_id.Identifier, str) else None
        if tag is None or tag not in self.db or not self.provider.historized(tag) or read is None:
            return _status(_BAD.BadHistoryOperationUnsupported)
        if item.IndexRange:
            return _status(_BAD.BadIndexRangeInvalid)
        resume = None
        if item.ContinuationPoint:
            resume = _unwrap(item.ContinuationPoint, tag)
            if resume is None:
                return _status(_BAD.BadContinuationPointInvalid)
        if params.ReleaseContinuationPoints:
            return ua.HistoryReadResult(HistoryData=ua.HistoryData())  # stateless: nothing to free
        try:
            outcome = await read(tag, resume)
        except ValueError:
            return _status(_BAD.BadContinuationPointInvalid if resume is not None else _BAD.BadInvalidArgument)
        except HistoryUnavailable as error:
            log.debug("history of %s unavailable: %s", tag, error)
            return _status(_BAD.BadResourceUnavailable)
        if isinstance(outcome, int):
            return _status(outcome)
        samples, variant_type, more = outcome
        timestamps = params.TimestampsToReturn

        def build() -> list[ua.DataValue]:
            return [_data_value(sample, variant_type, timestamps) for sample in samples]

        # ~2.5 ms per 1,000 values: a worker thread's, not the scan's.
        values = await self._run_blocking(build) if self._run_blocking is not None and len(samples) > 50 else build()
        result = ua.HistoryReadResult(HistoryData=ua.HistoryData(DataValues=values))
        if more is not None:
            result.ContinuationPoint = _wrap(tag, more)
        elif not values:
            result.StatusCode = ua.StatusCode(_BAD.GoodNoData)
        return result

    def _variant_type(self, tag: str) -> ua.VariantType:
        return VARIANT_TYPES[self.db[tag].definition.type]

    async def _raw(self, tag: str, details: ua.ReadRawModifiedDetails, resume: bytes | None) -> Any:
        limit = _limit(details.NumValuesPerNode)
        start, end = _epoch(details.StartTime), _epoch(details.EndTime)
        if details.ReturnBounds:
            page = await self.provider.read_raw(tag, start, end, limit, resume, bounds=True)  # type: ignore[call-arg]
        else:
            page = await self.provider.read_raw(tag, start, end, limit, resume)
        return page.samples, self._variant_type(tag), page.resume

    async def _processed(self, tag: str, details: ua.ReadProcessedDetails, kind: ua.NodeId, resume: bytes | None) -> Any:
        provider: Any = self.provider
        name = AGGREGATE_NAMES.get(kind.Identifier) if kind.NamespaceIndex == 0 else None
        if name is None or name not in provider.aggregates:
            return _BAD.BadAggregateNotSupported
        if not getattr(provider, "supports", lambda tag, name: True)(tag, name):
            return _BAD.BadAggregateNotSupported  # e.g. an average of a string
        start, end = _epoch(details.StartTime), _epoch(details.EndTime)
        interval = details.ProcessingInterval or 0.0
        if resume is None and (start is None or end is None or start == end or interval < 0):
            return _BAD.BadInvalidArgument  # all three are needed; start == end has no interval (Part 13 Table 12)
        config = _config(details.AggregateConfiguration)
        if isinstance(config, int):
            return config
        page = await provider.read_processed(tag, start, end, interval / 1000, name, config, MAX_RETURN_DATA_VALUES, resume)
        variant = (ua.VariantType.Double if name in _DOUBLE_AGGREGATES
                   else ua.VariantType.Int32 if name == "Count" else self._variant_type(tag))
        return page.samples, variant, page.resume

    async def _at_time(self, tag: str, details: ua.ReadAtTimeDetails, resume: bytes | None) -> Any:
        if resume is not None:
            raise ValueError("at-time reads give no continuation points")
        times = [_epoch(moment) for moment in details.ReqTimes or []]
        if any(moment is None for moment in times) or len(times) > MAX_RETURN_DATA_VALUES:
            return _BAD.BadInvalidArgument
        samples = await self.provider.read_at_time(tag, times, bool(details.UseSimpleBounds))  # type: ignore[attr-defined]
        return samples, self._variant_type(tag), None


# Part 13 aggregates by the NodeId of their AggregateFunction object (namespace 0).
AGGREGATE_NAMES: dict[int, str] = {
    getattr(ua.ObjectIds, attribute): attribute[len("AggregateFunction_"):]
    for attribute in dir(ua.ObjectIds) if attribute.startswith("AggregateFunction_")
}


def _status(code: int) -> ua.HistoryReadResult:
    return ua.HistoryReadResult(StatusCode=ua.StatusCode(code))


def _limit(requested: int) -> int:
    """NumValuesPerNode capped by the server's MaxReturnDataValues (0: no limit asked → the server's)."""
    return MAX_RETURN_DATA_VALUES if not requested or requested > MAX_RETURN_DATA_VALUES else int(requested)


def _config(configuration: ua.AggregateConfiguration | None) -> tuple[bool, int, int] | None | int:
    """The client's AggregateConfiguration, None for the server's defaults, or BadAggregateConfigurationRejected."""
    if configuration is None or configuration.UseServerCapabilitiesDefaults:
        return None
    bad, good = int(configuration.PercentDataBad), int(configuration.PercentDataGood)
    if not (0 <= bad <= 100 and 0 <= good <= 100) or good < 100 - bad:
        return _BAD.BadAggregateConfigurationRejected
    return bool(configuration.TreatUncertainAsBad), bad, good


def _epoch(moment: datetime | None) -> float | None:
    """A request's DateTime in epoch seconds; None when not given (null or the minimum DateTime)."""
    if moment is None:
        return None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    return None if moment < _EPOCH_MIN else moment.timestamp()


def _data_value(sample: Sample, variant_type: ua.VariantType, timestamps: ua.TimestampsToReturn) -> ua.DataValue:
    stamp = datetime.fromtimestamp(sample.time, timezone.utc)
    source = stamp if timestamps != ua.TimestampsToReturn.Server else None
    server = stamp if timestamps != ua.TimestampsToReturn.Source else None
    status = ua.StatusCode(sample.status) if sample.status is not None else STATUS_CODES[sample.quality]
    variant = ua.Variant(sample.value, variant_type) if sample.value is not None else ua.Variant()
    return ua.DataValue(variant, status, source, server)


def _wrap(tag: str, resume: bytes) -> bytes:
    name = tag.encode()
    return _CONTINUATION_MAGIC + struct.pack("<H", len(name)) + name + resume


def _unwrap(point: bytes, tag: str) -> bytes | None:
    """The provider's token from a continuation point given for `tag`, else None."""
    name = tag.encode()
    head = _CONTINUATION_MAGIC + struct.pack("<H", len(name)) + name
    return point[len(head):] if point.startswith(head) else None
