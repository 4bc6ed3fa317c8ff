"""What a data-change monitored item accepts and reports: filters, deadbands and queue sizes.

asyncua 2.1.0 (pinned) compares each sample with the *previous sample* under a deadband (a value
drifting slowly past the deadband is never reported), accepts a Percent deadband and ignores it
with a warning per sample, accepts a deadband on a String or Boolean and then fails on every
change, and revises a QueueSize of 0 to 10,000. Here, following OPC UA Part 4 (7.22.2
DataChangeFilter, 5.12.1.5 queue parameters) and Part 8 (6.2 PercentDeadband):

At CreateMonitoredItems / ModifyMonitoredItems (`change_filter`), per item:

    BadFilterNotAllowed                a deadband on a value that is not numeric (String, Boolean…)
                                       or on an attribute other than Value; an EventFilter on a value
    BadDeadbandFilterInvalid           a negative Absolute deadband; a Percent deadband outside
                                       0..100, or on a node without an EURange (Part 8) or whose
                                       EURange is open on one side (a float64 tag with only min or max)
    BadMonitoredItemFilterInvalid      an unknown Trigger
    BadMonitoredItemFilterUnsupported  an AggregateFilter, or a filter type nobody knows

The other items of the same request are created as usual.

When a sample is reported (`ChangeFilter.reports`): compared with the value *last reported* (put
in the queue), never with the previous sample:

- trigger Status: only a change of StatusCode;
- trigger StatusValue (the default): a change of StatusCode, or of the value — under a deadband
  only when |last reported − new| > deadband (Absolute: the given value; Percent: that
  percentage of the EURange's High − Low); NaN to number (or back) is a change;
- trigger StatusValueTimestamp: also a change of SourceTimestamp, unless a deadband is set (then
  it behaves as StatusValue, as Part 4 says).

Queue sizes (`revise_queue_size`): 0 and 1 → 1 (Part 4: 0 asks for the default, which is 1), at
most `MAX_QUEUE_SIZE`; a full queue drops its oldest notification. Event monitored items
(`revise_event_queue_size`): 0 → the server's default, 1,000, at most 10,000.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from asyncua import ua
from asyncua.server.address_space import AddressSpace
from asyncua.ua import uaprotocol_auto

# What the decoder makes of a DataChangeFilter (ua.DataChangeFilter is a hand-written subclass of it).
_DATA_CHANGE_FILTER = uaprotocol_auto.DataChangeFilter

# Most notifications one monitored item holds between two publishes. Enough for a 1 s publishing
# interval on a 10 ms task (100 samples); memory per item stays small even for clients that vanish.
MAX_QUEUE_SIZE = 100

_NUMERIC_DATA_TYPES = frozenset(ua.NodeId(type_id) for type_id in (
    ua.ObjectIds.SByte, ua.ObjectIds.Byte, ua.ObjectIds.Int16, ua.ObjectIds.UInt16, ua.ObjectIds.Int32,
    ua.ObjectIds.UInt32, ua.ObjectIds.Int64, ua.ObjectIds.UInt64, ua.ObjectIds.Float, ua.ObjectIds.Double,
    ua.ObjectIds.Number, ua.ObjectIds.Integer, ua.ObjectIds.UInteger, ua.ObjectIds.Duration,
))
_NUMERIC_VARIANTS = frozenset({
    ua.VariantType.SByte, ua.VariantType.Byte, ua.VariantType.Int16, ua.VariantType.UInt16, ua.VariantType.Int32,
    ua.VariantType.UInt32, ua.VariantType.Int64, ua.VariantType.UInt64, ua.VariantType.Float, ua.VariantType.Double,
})
_HAS_PROPERTY = ua.NodeId(ua.ObjectIds.HasProperty)
_OPEN_BOUND = 1.7976931348623157e308  # what an EURange carries for a side with no limit


class FilterRefused(Exception):
    """A monitored item's filter that does not fit its node (`code`: the OPC UA status)."""

    def __init__(self, code: int, detail: str) -> None:
        super().__init__(detail)
        self.code = code


def revise_queue_size(requested: int) -> int:
    """The queue size granted for a requested one (Part 4: 0 means the default, 1)."""
    return max(1, min(int(requested), MAX_QUEUE_SIZE))


DEFAULT_EVENT_QUEUE_SIZE = 1000
MAX_EVENT_QUEUE_SIZE = 10_000


def revise_event_queue_size(requested: int) -> int:
    """The queue size granted to an event monitored item (Part 4 7.21: 0 means the server's default).

    A queue of one would keep only the last event of a burst: a ConditionRefresh (RefreshStart,
    one event per active condition, RefreshEnd) or an alarm flood would lose all but one.
    """
    if requested <= 0:
        return DEFAULT_EVENT_QUEUE_SIZE
    return min(int(requested), MAX_EVENT_QUEUE_SIZE)


@dataclass(frozen=True)
class ChangeFilter:
    """When a new sample of a monitored value is reported (see the module docstring)."""

    trigger: ua.DataChangeTrigger = ua.DataChangeTrigger.StatusValue
    deadband: float | None = None  # absolute, in the value's units (a Percent one converted)

    def reports(self, last: ua.DataValue | None, new: ua.DataValue) -> bool:
        if last is None:
            return True
        if _status(last) != _status(new):
            return True
        if self.trigger == ua.DataChangeTrigger.Status:
            return False
        old_value, new_value = _value(last), _value(new)
        if self.deadband is None:
            if old_value != new_value:
                return True
            return self.trigger == ua.DataChangeTrigger.StatusValueTimestamp and last.SourceTimestamp != new.SourceTimestamp
        return _exceeds(old_value, new_value, self.deadband)


NO_FILTER = ChangeFilter()


def change_filter(aspace: AddressSpace, item: ua.ReadValueId, requested: Any) -> ChangeFilter:
    """The ChangeFilter for a data-change item's requested filter, or raise FilterRefused."""
    if requested is None or isinstance(requested, ua.ExtensionObject) and requested.TypeId.Identifier == 0:
        return NO_FILTER  # no filter (asyncua decodes a null ExtensionObject as an empty one)
    if isinstance(requested, ua.EventFilter):
        raise FilterRefused(ua.StatusCodes.BadFilterNotAllowed, "an EventFilter on a data item")
    if not isinstance(requested, _DATA_CHANGE_FILTER):
        raise FilterRefused(ua.StatusCodes.BadMonitoredItemFilterUnsupported, f"{type(requested).__name__} is not supported")
    try:
        trigger = ua.DataChangeTrigger(requested.Trigger)
    except ValueError:
        raise FilterRefused(ua.StatusCodes.BadMonitoredItemFilterInvalid, f"unknown Trigger {requested.Trigger}") from None
    kind = requested.DeadbandType
    if kind == ua.DeadbandType.None_:
        return ChangeFilter(trigger)
    if kind not in (ua.DeadbandType.Absolute, ua.DeadbandType.Percent):
        raise FilterRefused(ua.StatusCodes.BadDeadbandFilterInvalid, f"unknown DeadbandType {kind}")
    if item.AttributeId != ua.AttributeIds.Value or not _numeric(aspace, item.NodeId):
        raise FilterRefused(ua.StatusCodes.BadFilterNotAllowed, "a deadband needs a numeric Value")
    amount = float(requested.DeadbandValue)
    if kind == ua.DeadbandType.Absolute:
        if not amount >= 0:  # also NaN
            raise FilterRefused(ua.StatusCodes.BadDeadbandFilterInvalid, f"Absolute deadband {amount} is negative")
        return ChangeFilter(trigger, amount)
    if not 0.0 <= amount <= 100.0:
        raise FilterRefused(ua.StatusCodes.BadDeadbandFilterInvalid, f"Percent deadband {amount} is outside 0..100")
    span = _eu_span(aspace, item.NodeId)
    if span is None:
        raise FilterRefused(ua.StatusCodes.BadDeadbandFilterInvalid, "a Percent deadband needs an EURange")
    return ChangeFilter(trigger, amount / 100.0 * span)


def _status(value: ua.DataValue) -> int:
    return value.StatusCode.value if value.StatusCode is not None else 0


def _value(value: ua.DataValue) -> Any:
    return value.Value.Value if value.Value is not None else None


def _exceeds(old: Any, new: Any, deadband: float) -> bool:
    """Whether `new` is more than `deadband` away from `old` (element-wise for arrays)."""
    if isinstance(old, (list, tuple)) or isinstance(new, (list, tuple)):
        if not isinstance(old, (list, tuple)) or not isinstance(new, (list, tuple)) or len(old) != len(new):
            return True
        return any(_exceeds(a, b, deadband) for a, b in zip(old, new))
    if old is None or new is None or isinstance(old, bool) or isinstance(new, bool):
        return old != new
    old_nan, new_nan = math.isnan(old), math.isnan(new)
    if old_nan or new_nan:
        return old_nan != new_nan
    return abs(new - old) > deadband


def _numeric(aspace: AddressSpace, node_id: ua.NodeId) -> bool:
    data_type = aspace.read_attribute_value(node_id, ua.AttributeIds.DataType).Value
    if data_type is not None and data_type.Value in _NUMERIC_DATA_TYPES:
        return True
    current = aspace.read_attribute_value(node_id, ua.AttributeIds.Value).Value
    return current is not None and current.VariantType in _NUMERIC_VARIANTS


def _eu_span(aspace: AddressSpace, node_id: ua.NodeId) -> float | None:
    """High − Low of the node's EURange property, or None without a usable one."""
    node = aspace.get(node_id)
    if node is None:
        return None
    for reference in node.references:
        if reference.IsForward and reference.ReferenceTypeId == _HAS_PROPERTY and reference.BrowseName.Name == "EURange":
            stored = aspace.read_attribute_value(reference.NodeId, ua.AttributeIds.Value).Value
            eu_range = stored.Value if stored is not None else None
            if isinstance(eu_range, ua.Range):
                low, high = float(eu_range.Low), float(eu_range.High)
                # A float64 tag with only min or max publishes the largest double for its open
                # side (address_space.eu_range): no deadband can be a percentage of that.
                if max(abs(low), abs(high)) >= _OPEN_BOUND or not high > low:
                    return None
                return high - low
    return None
