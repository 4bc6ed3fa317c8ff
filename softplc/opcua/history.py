"""HistoryRead: what the OPC UA server answers, and the small interface a historian plugs into.

asyncua 2.1.0 (pinned) answers every HistoryRead with Good and no data — even for node ids that
do not exist — and logs a warning per call. `TagHistoryService` (installed as the server's
`history_manager`) answers per item instead, without logging:

    Good                              raw values of a historized tag (ReadRawModifiedDetails,
                                      IsReadModified false), with continuation points
    BadNodeIdUnknown                  no such node
    BadHistoryOperationUnsupported    a node without history (every tag until a historian is
                                      plugged in; folders, properties, the standard nodes), or a
                                      kind of read not offered: modified, processed (aggregates),
                                      at-time, events, annotations
    BadIndexRangeInvalid              an IndexRange (tags are scalars)
    BadContinuationPointInvalid       a continuation point this server did not give for that node

and for the whole request: BadNothingToDo (no node), BadTooManyOperations (more than
`MAX_NODES_PER_HISTORY_READ`, advertised as MaxNodesPerHistoryReadData), BadTimestampsToReturnInvalid
(Neither), BadHistoryOperationInvalid (no or unknown details).

## The provider interface (for the historian)

A historian gives the server a `HistoryProvider`: `OpcUaServer(settings, history=provider)`.

    historized(tag) -> bool
        Whether the tag has history. Its Variable then gets AccessLevel bit HistoryRead and
        Historizing = True (asked once, when the address space is built).
    async read_raw(tag, start, end, limit, resume) -> HistoryPage
        The tag's samples from `start` towards `end` (epoch seconds on the runtime clock, like
        tag timestamps; None: open on that side). Oldest first when start <= end (or end is
        None), newest first when start > end (or only end is given), as Part 11 orders them.
        At most `limit` samples (0: no limit). When more remain, `HistoryPage.resume` is an
        opaque bytes token of the provider's own making; the server wraps it (with the tag
        name) into the client's continuation point and passes it back as `resume` on the next
        call (with the same start, end and limit). A token the provider does not recognise:
        raise ValueError (the client gets BadContinuationPointInvalid). Continuation points are
        stateless: a released one needs no clean-up.

Each `Sample` is (time, value, quality); values have the tag's Python type, as in the tag
database. The provider is awaited on the event loop that runs the scan: do file or database work
in a thread (or the runtime clock's `run_blocking`). `NoHistory` (nothing historized) is the default.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, Protocol

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.server.history import HistoryManager

from softplc.opcua.variants import VARIANT_TYPES, STATUS_CODES
from softplc.tagdb import TagDatabase
from softplc.tags import Quality

MAX_NODES_PER_HISTORY_READ = 1000
_CONTINUATION_MAGIC = b"SPH1"
_EPOCH_MIN = datetime(1601, 1, 2, tzinfo=timezone.utc)  # before this a DateTime means "not given"


@dataclass(frozen=True)
class Sample:
    """One historical value of a tag."""

    time: float  # epoch seconds, runtime clock (as tag timestamps)
    value: Any
    quality: Quality = Quality.GOOD


@dataclass(frozen=True)
class HistoryPage:
    """Samples of one read, and where to resume when more remain (None: that was all)."""

    samples: Sequence[Sample]
    resume: bytes | None = None


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

    def __init__(self, iserver: Any, db: TagDatabase, namespace_index: int, provider: HistoryProvider) -> None:
        super().__init__(iserver)
        self.db = db
        self.ns = namespace_index
        self.provider = provider

    async def read_history(self, params: ua.HistoryReadParameters) -> list[ua.HistoryReadResult]:
        items = params.NodesToRead or []
        if not items:
            raise ServiceError(ua.StatusCodes.BadNothingToDo)
        if len(items) > MAX_NODES_PER_HISTORY_READ:
            raise ServiceError(ua.StatusCodes.BadTooManyOperations)
        if params.TimestampsToReturn not in (ua.TimestampsToReturn.Source, ua.TimestampsToReturn.Server, ua.TimestampsToReturn.Both):
            raise ServiceError(ua.StatusCodes.BadTimestampsToReturnInvalid)
        details = params.HistoryReadDetails
        if not isinstance(details, (ua.ReadRawModifiedDetails, ua.ReadProcessedDetails, ua.ReadAtTimeDetails,
                                    ua.ReadEventDetails, ua.ReadAnnotationDataDetails)):
            raise ServiceError(ua.StatusCodes.BadHistoryOperationInvalid)
        raw = isinstance(details, ua.ReadRawModifiedDetails) and not details.IsReadModified
        return [await self._read_one(item, details if raw else None, params) for item in items]

    async def _read_one(self, item: ua.HistoryReadValueId, raw: ua.ReadRawModifiedDetails | None,
                        params: ua.HistoryReadParameters) -> ua.HistoryReadResult:
        node_id = item.NodeId
        if node_id not in self.iserver.aspace:
            return _status(ua.StatusCodes.BadNodeIdUnknown)
        tag = node_id.Identifier if node_id.NamespaceIndex == self.ns and isinstance(node_id.Identifier, str) else None
        if tag is None or tag not in self.db or not self.provider.historized(tag) or raw is None:
            return _status(ua.StatusCodes.BadHistoryOperationUnsupported)
        if item.IndexRange:
            return _status(ua.StatusCodes.BadIndexRangeInvalid)
        resume = None
        if item.ContinuationPoint:
            resume = _unwrap(item.ContinuationPoint, tag)
            if resume is None:
                return _status(ua.StatusCodes.BadContinuationPointInvalid)
        if params.ReleaseContinuationPoints:
            return ua.HistoryReadResult(HistoryData=ua.HistoryData())  # stateless: nothing to free
        try:
            page = await self.provider.read_raw(tag, _epoch(raw.StartTime), _epoch(raw.EndTime), int(raw.NumValuesPerNode), resume)
        except ValueError:
            return _status(ua.StatusCodes.BadContinuationPointInvalid)
        variant_type = VARIANT_TYPES[self.db[tag].definition.type]
        values = [_data_value(sample, variant_type, params.TimestampsToReturn) for sample in page.samples]
        result = ua.HistoryReadResult(HistoryData=ua.HistoryData(DataValues=values))
        if page.resume is not None:
            result.ContinuationPoint = _wrap(tag, page.resume)
        return result


def _status(code: int) -> ua.HistoryReadResult:
    return ua.HistoryReadResult(StatusCode=ua.StatusCode(code))


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
    return ua.DataValue(ua.Variant(sample.value, variant_type), STATUS_CODES[sample.quality], source, server)


def _wrap(tag: str, resume: bytes) -> bytes:
    name = tag.encode()
    return _CONTINUATION_MAGIC + struct.pack("<H", len(name)) + name + resume


def _unwrap(point: bytes, tag: str) -> bytes | None:
    """The provider's token from a continuation point given for `tag`, else None."""
    name = tag.encode()
    head = _CONTINUATION_MAGIC + struct.pack("<H", len(name)) + name
    return point[len(head):] if point.startswith(head) else None
