"""What the server tells clients about its history: Server/ServerCapabilities and HistoryServerCapabilities.

Part 11 §5.4.2 and Part 13 §4.4: `HistoryServerCapabilities` says which kinds of history access
are offered (data, not events; no inserts, updates or deletes) and `MaxReturnDataValues`; the
`AggregateFunctions` folders of both ServerCapabilities and HistoryServerCapabilities organize the
standard AggregateFunction objects the historian computes, so a client can discover them by
browsing. asyncua's standard address space has every node but leaves the values empty and the
folders without references.
"""

from __future__ import annotations

from collections.abc import Collection

from asyncua import Server, ua

from softplc.adapters.opcua.history import AGGREGATE_NAMES, MAX_RETURN_DATA_VALUES

_ids = ua.ObjectIds
_FOLDERS = (_ids.Server_ServerCapabilities_AggregateFunctions, _ids.HistoryServerCapabilities_AggregateFunctions)
_NOT_OFFERED = (  # Booleans that are false: writing history, events, annotations
    _ids.HistoryServerCapabilities_AccessHistoryEventsCapability, _ids.HistoryServerCapabilities_InsertDataCapability,
    _ids.HistoryServerCapabilities_ReplaceDataCapability, _ids.HistoryServerCapabilities_UpdateDataCapability,
    _ids.HistoryServerCapabilities_DeleteRawCapability, _ids.HistoryServerCapabilities_DeleteAtTimeCapability,
    _ids.HistoryServerCapabilities_InsertEventCapability, _ids.HistoryServerCapabilities_ReplaceEventCapability,
    _ids.HistoryServerCapabilities_UpdateEventCapability, _ids.HistoryServerCapabilities_DeleteEventCapability,
    _ids.HistoryServerCapabilities_InsertAnnotationCapability,
)


async def advertise_history(server: Server, aggregates: Collection[str], *, data: bool) -> None:
    """Fill HistoryServerCapabilities and link the offered aggregates (Part 13 names) into both AggregateFunctions folders.

    Call before the attribute service that guards tag writes is installed (it lets nothing else be written).
    """
    boolean, unsigned = ua.VariantType.Boolean, ua.VariantType.UInt32
    values = [(_ids.HistoryServerCapabilities_AccessHistoryDataCapability, ua.Variant(data, boolean)),
              (_ids.HistoryServerCapabilities_MaxReturnDataValues, ua.Variant(MAX_RETURN_DATA_VALUES if data else 0, unsigned)),
              (_ids.HistoryServerCapabilities_MaxReturnEventValues, ua.Variant(0, unsigned)),
              # Our source timestamps are the server's own clock (the runtime's): it can return either.
              (_ids.HistoryServerCapabilities_ServerTimestampSupported, ua.Variant(data, boolean))]
    values += [(node, ua.Variant(False, boolean)) for node in _NOT_OFFERED]
    for node, value in values:
        await server.get_node(ua.NodeId(node)).write_value(value)
    by_name = {name: node for node, name in AGGREGATE_NAMES.items()}
    for folder in _FOLDERS:
        node = server.get_node(ua.NodeId(folder))
        for name in sorted(aggregates):
            await node.add_reference(ua.NodeId(by_name[name]), ua.NodeId(_ids.Organizes), forward=True, bidirectional=True)
