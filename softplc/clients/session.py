"""A client session on a running softplc: its tags by name, their values, quality and forced mark.

Tags are the Variables of softplc's namespace (`urn:softplc:tags`), NodeId `ns=<index>;s=<tag
name>`. A tag's type comes from its DataType attribute, its range from its EURange property,
and a forced tag is served with the StatusCode GoodLocalOverride (softplc/core/forcing.py).
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from asyncua import Client, ua

from softplc.core.datatypes import DataType
from softplc.core.tags import Access, Quality, TagDef
from softplc.protocols.opcua_variants import DATA_TYPE_IDS
from softplc.util.suggest import did_you_mean
from softplc.util.tasks import within

if TYPE_CHECKING:
    from softplc.clients.login import Login

SOFTPLC_NAMESPACE = "urn:softplc:tags"
_DATA_TYPES = {node_id: data_type for data_type, node_id in DATA_TYPE_IDS.items()}
_OBJECTS_FOLDER = ua.NodeId(ua.ObjectIds.ObjectsFolder)
_HIERARCHICAL = ua.NodeId(ua.ObjectIds.HierarchicalReferences)
_LARGEST_DOUBLE = 1.7976931348623157e308
_WRITE = ua.AccessLevel.CurrentWrite.mask


class NotSoftplc(Exception):
    """The server is no softplc runtime (it has no tag namespace)."""


class UnknownTags(Exception):
    """Names that are no tag of the server; the message lists them with a hint each."""

    def __init__(self, names: list[str], hints: dict[str, str]) -> None:
        super().__init__("; ".join(f"no such tag '{name}'{hints.get(name, '')}" for name in names))
        self.names = names


@dataclass(frozen=True)
class Reading:
    """One tag's value as served: its quality, whether it is forced, and when it last changed."""

    tag: str
    value: Any
    quality: Quality
    forced: bool
    timestamp: datetime | None
    status: str = "Good"  # the StatusCode's name
    single: bool = False  # a Float (float32) value: shown with the digits a float32 has

    @classmethod
    def from_data_value(cls, tag: str, data: ua.DataValue) -> Reading:
        code = data.StatusCode.value if data.StatusCode is not None else 0
        forced = code == ua.StatusCodes.GoodLocalOverride
        severity = code >> 30  # 0 good, 1 uncertain, 2/3 bad (OPC UA Part 4, 7.39)
        quality = Quality.GOOD if severity == 0 else Quality.UNCERTAIN if severity == 1 else Quality.BAD
        value = data.Value.Value if data.Value is not None else None
        stamp = data.SourceTimestamp or data.ServerTimestamp
        if stamp is not None and stamp.tzinfo is None:
            stamp = stamp.replace(tzinfo=timezone.utc)
        single = data.Value is not None and data.Value.VariantType == ua.VariantType.Float
        return cls(tag, value, quality, forced, stamp, ua.StatusCode(code).name if code else "Good", single)


@dataclass(frozen=True)
class TagInfo:
    """What a client can learn of a tag's declaration: its type, range and whether this session may write it."""

    definition: TagDef
    writable: bool


class LiveSession:
    """Tag-level reads, writes and browsing over a connected asyncua Client."""

    def __init__(self, client: Client, namespace_index: int) -> None:
        self.client = client
        self.ns = namespace_index
        self._names: list[str] | None = None

    @classmethod
    async def open(cls, client: Client, namespace: str = SOFTPLC_NAMESPACE) -> LiveSession:
        """A session on the runtime serving its tags in `namespace` (a URI); raises NotSoftplc."""
        namespaces = await client.get_namespace_array()
        if namespace not in namespaces:
            hint = "" if namespace == SOFTPLC_NAMESPACE else " (is --namespace right?)"
            raise NotSoftplc(f"the server has no namespace {namespace}: it is not a softplc runtime{hint}")
        return cls(client, namespaces.index(namespace))

    def node_id(self, tag: str) -> ua.NodeId:
        return ua.NodeId(tag, self.ns)

    async def tag_names(self) -> list[str]:
        """Every tag of the server, in address-space order (browsed once per session)."""
        if self._names is None:
            self._names = await self._browse_tags()
        return self._names

    async def _browse_tags(self) -> list[str]:
        names: list[str] = []
        level = [_OBJECTS_FOLDER]
        while level:
            descriptions = []
            for node_id in level:
                description = ua.BrowseDescription()
                description.NodeId = node_id
                description.BrowseDirection = ua.BrowseDirection.Forward
                description.ReferenceTypeId = _HIERARCHICAL
                description.IncludeSubtypes = True
                description.NodeClassMask = ua.NodeClass.Object | ua.NodeClass.Variable
                description.ResultMask = ua.BrowseResultMask.All
                descriptions.append(description)
            parameters = ua.BrowseParameters()
            parameters.NodesToBrowse = descriptions
            results = await self.client.uaclient.browse(parameters)
            next_level = []
            for result in results:
                references = list(result.References)
                continuation = result.ContinuationPoint
                while continuation:  # a server may hand out long folders in parts
                    more = await self.client.uaclient.browse_next(ua.BrowseNextParameters(ContinuationPoints=[continuation]))
                    references.extend(more[0].References)
                    continuation = more[0].ContinuationPoint
                for reference in references:
                    node_id = reference.NodeId
                    if node_id.NamespaceIndex != self.ns:
                        continue
                    if reference.NodeClass == ua.NodeClass.Variable and isinstance(node_id.Identifier, str):
                        names.append(node_id.Identifier)
                    elif reference.NodeClass == ua.NodeClass.Object:
                        next_level.append(node_id)
            level = next_level
        return list(dict.fromkeys(names))

    async def match(self, patterns: list[str]) -> list[str]:
        """The tags matching any of the globs (`t01_*`, `r0?_xpos`), in pattern order; raises UnknownTags for one that matches none.

        Exact names alone are returned as given, without browsing: a browse of the whole
        address space holds the server's loop for a while (0.15-0.4 s per level with 1,000
        alarm conditions), and `read`/`describe` name an unknown tag anyway (UnknownTags).
        """
        if not any(_is_glob(pattern) for pattern in patterns):
            return list(dict.fromkeys(patterns))
        names = await self.tag_names()
        chosen: dict[str, None] = {}
        unmatched = []
        for pattern in patterns:
            if not _is_glob(pattern):
                if pattern in names:
                    chosen[pattern] = None
                else:
                    unmatched.append(pattern)
                continue
            found = [name for name in names if fnmatch.fnmatchcase(name, pattern)]
            if not found:
                unmatched.append(pattern)
            chosen.update(dict.fromkeys(found))
        if unmatched:
            raise UnknownTags(unmatched, {p: did_you_mean(p, names) if not _is_glob(p) else " (no tag matches this pattern)" for p in unmatched})
        return list(chosen)

    async def read(self, tags: list[str]) -> list[Reading]:
        """The current value of each tag (one Read); raises UnknownTags for names the server does not know."""
        values = await self._read_attribute(tags, ua.AttributeIds.Value)
        unknown = [tag for tag, data in zip(tags, values) if _unknown(data)]
        if unknown:
            names = await self.tag_names()
            raise UnknownTags(unknown, {name: did_you_mean(name, names) for name in unknown})
        return [Reading.from_data_value(tag, data) for tag, data in zip(tags, values)]

    async def describe(self, tags: list[str]) -> dict[str, TagInfo]:
        """Each tag's type, range and this session's right to write it (one Read); raises UnknownTags."""
        reads = []
        for tag in tags:
            reads += [(self.node_id(tag), ua.AttributeIds.DataType), (self.node_id(tag), ua.AttributeIds.UserAccessLevel),
                      (ua.NodeId(f"{tag}/EURange", self.ns), ua.AttributeIds.Value)]
        results = await self._read(reads)
        infos: dict[str, TagInfo] = {}
        unknown = []
        for index, tag in enumerate(tags):
            data_type, access, eu_range = results[3 * index: 3 * index + 3]
            kind = _DATA_TYPES.get(data_type.Value.Value) if not _unknown(data_type) and data_type.Value is not None else None
            if kind is None:
                unknown.append(tag)
                continue
            low, high = _bounds(kind, eu_range)
            writable = bool(access.Value is not None and isinstance(access.Value.Value, int) and access.Value.Value & _WRITE)
            definition = TagDef(tag, kind, kind.default, access=Access.RW if writable else Access.RO, min=low, max=high,
                                runtime_only=tag.startswith("_sys."))
            infos[tag] = TagInfo(definition, writable)
        if unknown:
            names = await self.tag_names()
            raise UnknownTags(unknown, {name: did_you_mean(name, names) for name in unknown})
        return infos

    async def _read_attribute(self, tags: list[str], attribute: ua.AttributeIds) -> list[ua.DataValue]:
        return await self._read([(self.node_id(tag), attribute) for tag in tags])

    async def _read(self, items: list[tuple[ua.NodeId, ua.AttributeIds]]) -> list[ua.DataValue]:
        parameters = ua.ReadParameters()
        for node_id, attribute in items:
            value = ua.ReadValueId()
            value.NodeId = node_id
            value.AttributeId = attribute
            parameters.NodesToRead.append(value)
        parameters.TimestampsToReturn = ua.TimestampsToReturn.Both
        return await self.client.uaclient.read(parameters)

    async def write(self, values: list[tuple[str, ua.Variant]]) -> list[ua.StatusCode]:
        """One Write of all the values; one StatusCode per item."""
        nodes = [self.client.get_node(self.node_id(tag)) for tag, _ in values]
        return await self.client.write_values(nodes, [ua.DataValue(variant) for _, variant in values], raise_on_partial_error=False)


@asynccontextmanager
async def open_live_session(login: Login) -> AsyncIterator[LiveSession]:
    """Connect with `login` and open a LiveSession; disconnect when done. Raises LoginError, NotSoftplc."""
    from softplc.clients.login import connect

    client = await connect(login)
    try:
        yield await LiveSession.open(client, login.namespace)
    finally:
        try:
            await within(login.timeout, client.disconnect())
        except Exception:  # the server is gone already: nothing to close politely
            client.disconnect_socket()


def _is_glob(pattern: str) -> bool:
    return any(char in pattern for char in "*?[")


def _unknown(data: ua.DataValue) -> bool:
    return data.StatusCode is not None and data.StatusCode.value in (ua.StatusCodes.BadNodeIdUnknown, ua.StatusCodes.BadAttributeIdInvalid)


def _bounds(kind: DataType, eu_range: ua.DataValue) -> tuple[float | None, float | None]:
    """The tag's min and max from its EURange (None where the range is only the type's own limit)."""
    if _unknown(eu_range) or eu_range.Value is None or not isinstance(eu_range.Value.Value, ua.Range):
        return None, None
    limits = kind.limits or (-math.inf, math.inf)
    low, high = eu_range.Value.Value.Low, eu_range.Value.Value.High
    return _bound(low, limits[0]), _bound(high, limits[1])


def _bound(value: float, limit: float) -> float | None:
    if abs(value) >= _LARGEST_DOUBLE or value == limit:
        return None
    return int(value) if float(value).is_integer() else value
