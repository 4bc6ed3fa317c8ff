"""The OPC UA side of an alarm: its condition's event object and its nodes (for conditions.py).

asyncua 2.1 has the event classes (`asyncua.common.event_objects`) but fills none of the
condition fields; `new_event` makes a condition's event object once, `note` follows every alarm
event of the condition (cheaply), and `fill` brings the object to the latest one (with a new
EventId) when a client is to get it. The nodes are made directly as
asyncua `NodeData`, as `address_space.py` makes the tags' (its attribute service lets clients
write nothing but tag values).
"""

from __future__ import annotations

import uuid
from datetime import datetime, timezone
from typing import Any

from asyncua import ua
from asyncua.server.address_space import AttributeValue, NodeData

from softplc.core.alarms import AlarmSnapshot, AlarmState, ShelveKind
from softplc.core.events import Event

_I = ua.ObjectIds
_SHELVING = {None: ("Unshelved", _I.ShelvedStateMachineType_Unshelved), ShelveKind.TIMED: ("TimedShelved", _I.ShelvedStateMachineType_TimedShelved),
             ShelveKind.ONE_SHOT: ("OneShotShelved", _I.ShelvedStateMachineType_OneShotShelved)}
_LEVEL_FIELDS = {"hihi": "HighHighLimit", "hi": "HighLimit", "lo": "LowLimit", "lolo": "LowLowLimit"}
_LEVEL_TEXT = {"hihi": "HighHigh", "hi": "High", "lo": "Low", "lolo": "LowLow"}


class EventTypeId(ua.NodeId):
    """An event's EventType that also equals its supertypes' NodeIds.

    asyncua's event filter evaluates OfType as plain equality of EventType; Part 4 (7.7.3)
    wants every subtype to match, so a client filtering OfType AcknowledgeableConditionType
    (node-opcua's alarm monitoring, UaExpert) would get none of our LimitAlarmType events.
    Only the filter compares EventTypes; everywhere else this is an ordinary NodeId.
    """

    __slots__ = ()
    supertypes: dict[Any, frozenset[ua.NodeId]] = {}

    def __eq__(self, other: object) -> bool:
        if ua.NodeId.__eq__(self, other):
            return True
        return isinstance(other, ua.NodeId) and other in EventTypeId.supertypes.get(self.Identifier, frozenset())

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    __hash__ = ua.NodeId.__hash__

    @classmethod
    def of(cls, aspace: Any, type_id: int) -> EventTypeId:
        """The EventType id of `type_id`, knowing its supertypes from the address space."""
        found: set[ua.NodeId] = set()
        current: ua.NodeId | None = ua.NodeId(type_id)
        while current is not None and current in aspace:
            parent = next((ref.NodeId for ref in aspace[current].references
                           if not ref.IsForward and ref.ReferenceTypeId == ua.NodeId(_I.HasSubtype)), None)
            if parent is not None:
                found.add(ua.NodeId(parent.Identifier, parent.NamespaceIndex))
            current = parent
        cls.supertypes[type_id] = frozenset(found)
        return cls(type_id)


_EXTRA = {
    "NodeId": ua.VariantType.NodeId,  # the ConditionId (selected with AttributeId NodeId on ConditionType)
    "ShelvingState": ua.VariantType.LocalizedText, "ShelvingState/CurrentState": ua.VariantType.LocalizedText,
    "ShelvingState/CurrentState/Id": ua.VariantType.NodeId, "ShelvingState/UnshelveTime": ua.VariantType.Double,
}
_TYPE_FIXES = {_I.UtcTime: ua.VariantType.DateTime, _I.Duration: ua.VariantType.Double, _I.AudioDataType: ua.VariantType.ByteString}


def new_event(event_class: type, node_id: ua.NodeId, source: ua.NodeId, snapshot: Any) -> Any:
    """The event object of one condition (`snapshot`: its name, tag), made once and refilled per event."""
    event = event_class(sourcenode=source)
    for name, variant_type in _EXTRA.items():
        event.add_property(name, None, variant_type)
    fix_types(event)
    event.NodeId = node_id
    event.SourceName = snapshot.tag
    event.ConditionName = snapshot.name
    event.ConditionClassId = ua.NodeId(_I.ProcessConditionClassType)
    event.ConditionClassName = ua.LocalizedText("Process")
    event.BranchId = ua.NodeId()
    event.InputNode = source
    event.Quality = ua.StatusCode(ua.StatusCodes.Good)
    event.LocalTime = ua.TimeZoneDataType()
    return event


def fix_types(event: Any) -> None:
    """asyncua declares UtcTime and Duration fields with a NodeId where a VariantType belongs."""
    for name, data_type in list(event.data_types.items()):
        if isinstance(data_type, ua.NodeId):
            event.data_types[name] = _TYPE_FIXES.get(data_type.Identifier, ua.VariantType.Variant)


_STATES = ("ActiveState", "AckedState", "SuppressedState", "OutOfServiceState", "LatchedState")


def note(condition: Any, event: Event) -> None:
    """Follow one event of the condition, delivered or not: its latest state, since when each two-state variable holds.

    Cheap (a flood brings thousands a second); `fill` makes the event object only when a client
    is to get it.
    """
    snapshot: AlarmSnapshot = event.data["alarm"]
    states = (snapshot.active, snapshot.acknowledged, snapshot.suppressed, snapshot.out_of_service, snapshot.state is AlarmState.LATCHED)
    if states != condition.states:
        for name, before, after in zip(_STATES, condition.states, states):
            if before != after:
                condition.changed_at[name] = event.time
        condition.states = states
    condition.last_severity = condition.severity or snapshot.severity
    condition.severity = snapshot.severity
    condition.retained = snapshot.state.annunciated or snapshot.active
    condition.latest = event


def fill(condition: Any, shelve_max: float) -> None:
    """Bring the condition's event object to its latest noted event, with a new EventId."""
    event: Event = condition.latest
    if condition.filled is event:
        return
    condition.filled = event
    snapshot: AlarmSnapshot = event.data["alarm"]
    target = condition.event
    data = event.data
    now = datetime.now(timezone.utc)
    stamp = datetime.fromtimestamp(event.time, timezone.utc)
    event_id = uuid.uuid4().bytes
    condition.event_ids.append(event_id)
    state = snapshot.state
    target.EventId = event_id
    target.Time, target.ReceiveTime = stamp, now
    target.Message = ua.LocalizedText(snapshot.message)
    target.LastSeverity, target.Severity = condition.last_severity, snapshot.severity
    target.Retain = condition.retained
    target.ClientUserId = data.get("user", "")
    target.Comment = ua.LocalizedText(snapshot.comment)
    enabled = not snapshot.out_of_service
    target.EnabledState, target.__dict__["EnabledState/Id"] = ua.LocalizedText("Enabled" if enabled else "Disabled"), enabled
    level = _LEVEL_TEXT.get(snapshot.level, "")
    active_text = ("Active " + level).strip() if snapshot.active else "Inactive"
    changed_at = condition.changed_at
    _state(target, "ActiveState", snapshot.active, active_text, changed_at)
    target.__dict__["ActiveState/EffectiveDisplayName"] = ua.LocalizedText(active_text)
    _state(target, "AckedState", snapshot.acknowledged, "Acknowledged" if snapshot.acknowledged else "Unacknowledged", changed_at)
    _state(target, "SuppressedState", snapshot.suppressed, "Suppressed" if snapshot.suppressed else "Unsuppressed", changed_at)
    _state(target, "OutOfServiceState", snapshot.out_of_service, "Out of Service" if snapshot.out_of_service else "In Service", changed_at)
    latched = state is AlarmState.LATCHED
    _state(target, "LatchedState", latched, "Latched" if latched else "Unlatched", changed_at)
    shelving = snapshot.shelving
    text, state_id = _SHELVING[shelving.kind if shelving is not None else None]
    target.ShelvingState = target.__dict__["ShelvingState/CurrentState"] = ua.LocalizedText(text)
    target.__dict__["ShelvingState/CurrentState/Id"] = ua.NodeId(state_id)
    target.__dict__["ShelvingState/UnshelveTime"] = max(0.0, (shelving.until - event.time) * 1000.0) if shelving is not None else 0.0
    target.SuppressedOrShelved = snapshot.suppressed or shelving is not None or snapshot.out_of_service
    target.MaxTimeShelved = shelve_max * 1000.0
    for level_name, limit in snapshot.limits:
        if hasattr(target, _LEVEL_FIELDS[level_name]):
            setattr(target, _LEVEL_FIELDS[level_name], float(limit))


def _state(target: Any, name: str, value: bool, text: str, changed_at: dict[str, float]) -> None:
    fields = target.__dict__
    setattr(target, name, ua.LocalizedText(text))
    fields[f"{name}/Id"] = value
    fields[f"{name}/TransitionTime"] = datetime.fromtimestamp(changed_at[name], timezone.utc)


# -- nodes ----------------------------------------------------------------------------------------


def attribute_value(value: Any, variant_type: ua.VariantType) -> AttributeValue:
    return AttributeValue(ua.DataValue(ua.Variant(value, variant_type)))


def make_node(aspace: Any, node_id: ua.NodeId, browse_name: ua.QualifiedName, description: str) -> NodeData:
    node = NodeData(node_id)
    node.attributes = {
        ua.AttributeIds.NodeId: attribute_value(node_id, ua.VariantType.NodeId),
        ua.AttributeIds.BrowseName: attribute_value(browse_name, ua.VariantType.QualifiedName),
        ua.AttributeIds.NodeClass: attribute_value(ua.NodeClass.Object, ua.VariantType.Int32),
        ua.AttributeIds.DisplayName: attribute_value(ua.LocalizedText(browse_name.Name), ua.VariantType.LocalizedText),
        ua.AttributeIds.Description: attribute_value(ua.LocalizedText(description), ua.VariantType.LocalizedText),
        ua.AttributeIds.WriteMask: attribute_value(0, ua.VariantType.UInt32),
        ua.AttributeIds.UserWriteMask: attribute_value(0, ua.VariantType.UInt32),
        ua.AttributeIds.EventNotifier: attribute_value(0, ua.VariantType.Byte),
    }
    aspace[node_id] = node
    return node


def _attribute(node: NodeData, attribute: ua.AttributeIds) -> Any:
    return node.attributes[attribute].value.Value.Value  # type: ignore[union-attr]


def link(parent: NodeData, child: NodeData, reference: int, type_definition: ua.NodeId | None, *, inverse: bool = True) -> None:
    """Reference parent → child (and the inverse on the child unless it is a shared method); the child's type if new."""
    node_class = _attribute(child, ua.AttributeIds.NodeClass)
    parent.references.append(ua.ReferenceDescription(
        ReferenceTypeId=ua.NodeId(reference), IsForward=True, NodeId=child.nodeid, BrowseName=_attribute(child, ua.AttributeIds.BrowseName),
        DisplayName=_attribute(child, ua.AttributeIds.DisplayName), NodeClass=node_class, TypeDefinition=type_definition or ua.NodeId(),
    ))
    if inverse:
        child.references.append(ua.ReferenceDescription(
            ReferenceTypeId=ua.NodeId(reference), IsForward=False, NodeId=parent.nodeid, BrowseName=_attribute(parent, ua.AttributeIds.BrowseName),
            DisplayName=_attribute(parent, ua.AttributeIds.DisplayName), NodeClass=_attribute(parent, ua.AttributeIds.NodeClass),
        ))
    if type_definition is not None:
        child.references.append(ua.ReferenceDescription(
            ReferenceTypeId=ua.NodeId(_I.HasTypeDefinition), IsForward=True, NodeId=type_definition, NodeClass=ua.NodeClass.ObjectType,
        ))


def parent_folder(aspace: Any, node_id: ua.NodeId) -> ua.NodeId | None:
    """The folder that organizes a tag's Variable."""
    if node_id not in aspace:
        return None
    for reference in aspace[node_id].references:
        if not reference.IsForward and reference.ReferenceTypeId == ua.NodeId(_I.Organizes):
            return reference.NodeId
    return None


