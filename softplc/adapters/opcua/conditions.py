"""OPC UA Alarms & Conditions (Part 9) for the runtime's alarms: events, methods, ConditionRefresh.

asyncua 2.1 has the event types but none of the condition logic; this module adds what softplc
needs on top of the `alarms.*` commands and `alarm` events (it never imports the engine):

- one condition object per alarm under `Objects/Alarms` (`ns=N;s=alarms.<name>`, typed
  AlarmConditionType, LimitAlarmType or OffNormalAlarmType, with a `ShelvingState` child and
  HasComponent references to the type's methods); the watched tag HasCondition → it;
- an event for every transition (AlarmConditionType fields: EventId, SourceNode, SourceName,
  Time, Severity, Message, ConditionName, Retain, Enabled/Active/Acked/Suppressed/OutOfService/
  Latched states, ShelvingState, SuppressedOrShelved, MaxTimeShelved, Comment, ClientUserId…),
  emitted on the Server object and on the folder of the watched tag (both are event notifiers),
  delivered off the scan by `condition_delivery.py` (paced; an overflow event where a flood or a
  slow client made it leave events out);
- methods, role-checked by the command registry: Acknowledge, AddComment, TimedShelve(2),
  OneShotShelve(2), Unshelve(2), Enable/Disable and PlaceInService/RemoveFromService (out of
  service: engineer), ConditionRefresh and ConditionRefresh2. Confirm is not supported.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from asyncua import Server, ua
from asyncua.common import event_objects

from softplc.adapters.opcua.commands import call_command, current_origin, current_session_id, install_caller_context
from softplc.adapters.opcua.condition_delivery import ConditionDelivery
from softplc.adapters.opcua.condition_events import (
    EventTypeId,
    attribute_value,
    fill,
    fix_types,
    link,
    make_node,
    new_event,
    parent_folder,
)
from softplc.core.alarms import NothingToAcknowledge, NotShelved, ServiceUnchanged, ShelvingTimeOutOfRange, UnknownAlarm
from softplc.core.events import Event
from softplc.core.tagdb import Origin

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

ALARMS_FOLDER = "/Alarms"
INTERNAL = Origin("opcua", role=None)
_I = ua.ObjectIds
_SERVER = ua.NodeId(_I.Server)
_EVENT_CLASSES = {"limit": (event_objects.LimitAlarm, _I.LimitAlarmType), "discrete": (event_objects.OffNormalAlarm, _I.OffNormalAlarmType)}
_REFUSALS = {NothingToAcknowledge: ua.StatusCodes.BadConditionBranchAlreadyAcked, NotShelved: ua.StatusCodes.BadConditionNotShelved,
             ShelvingTimeOutOfRange: ua.StatusCodes.BadShelvingTimeOutOfRange, UnknownAlarm: ua.StatusCodes.BadNodeIdUnknown}
_CONDITION_METHODS = (_I.AcknowledgeableConditionType_Acknowledge, _I.AcknowledgeableConditionType_Confirm, _I.ConditionType_AddComment,
                      _I.ConditionType_Enable, _I.ConditionType_Disable, _I.AlarmConditionType_PlaceInService, _I.AlarmConditionType_RemoveFromService)
_SHELVING_METHODS = (_I.ShelvedStateMachineType_TimedShelve, _I.ShelvedStateMachineType_OneShotShelve, _I.ShelvedStateMachineType_Unshelve)
MAX_EVENT_IDS = 32  # EventIds of a condition that Acknowledge and AddComment still accept


@dataclass
class _Condition:
    name: str
    node_id: ua.NodeId
    shelving_id: ua.NodeId
    source: ua.NodeId
    emitting: list[ua.NodeId]
    event: Any
    event_ids: deque[bytes] = field(default_factory=lambda: deque(maxlen=MAX_EVENT_IDS))
    retained: bool = False
    severity: int = 0
    last_severity: int = 0
    states: tuple[bool | None, ...] = (None,) * 5  # Active, Acked, Suppressed, OutOfService, Latched as last noted
    changed_at: dict[str, float] = field(default_factory=dict)  # when each of them last changed (wall-clock s)
    latest: Event | None = None  # the last alarm event noted
    filled: Event | None = None  # the one the event object holds


class AlarmConditions:
    """The runtime's alarms as OPC UA conditions (see the module docstring)."""

    def __init__(self, server: Server, plant: Plant, namespace_index: int) -> None:
        self.server = server
        self.plant = plant
        self.ns = namespace_index
        self.by_node: dict[ua.NodeId, _Condition] = {}
        self.by_name: dict[str, _Condition] = {}
        self.notifiers: list[ua.NodeId] = [_SERVER]
        self.shelve_max = 0.0
        self.delivery: ConditionDelivery | None = None
        self._task: asyncio.Task[None] | None = None
        self._unsubscribe: Any = None

    @classmethod
    async def install(cls, server: Server, plant: Plant, namespace_index: int) -> AlarmConditions | None:
        """Conditions for every alarm of the plant (None when it has no alarms adapter)."""
        if "alarms.list" not in plant.commands:
            return None
        conditions = cls(server, plant, namespace_index)
        install_caller_context(server.iserver)
        snapshots = [AlarmSnapshotView(item) for item in await plant.commands.call("alarms.list", {}, INTERNAL)]
        conditions.shelve_max = float((await plant.commands.call("alarms.summary", {}, INTERNAL))["shelve_max"])
        conditions._build(snapshots)
        conditions._bind_methods()
        conditions.delivery = delivery = ConditionDelivery(server, conditions.by_name, conditions.shelve_max)
        conditions._unsubscribe = plant.events.subscribe(delivery.put, kinds=("alarm",))
        conditions._task = asyncio.get_running_loop().create_task(delivery.run(), name="opcua-conditions")
        return conditions

    async def stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._task is not None:
            self._task.cancel()
            self._task = None

    # -- address space --------------------------------------------------------------------

    def _build(self, snapshots: list[AlarmSnapshotView]) -> None:
        aspace = self.server.iserver.aspace
        objects = aspace[ua.NodeId(_I.ObjectsFolder)]
        folder = make_node(aspace, ua.NodeId(ALARMS_FOLDER, self.ns), ua.QualifiedName("Alarms", self.ns), "the plant's alarms (OPC UA conditions)")
        folder.attributes[ua.AttributeIds.EventNotifier] = attribute_value(0, ua.VariantType.Byte)
        link(objects, folder, _I.Organizes, ua.NodeId(_I.FolderType))
        server = aspace[_SERVER]
        for snapshot in snapshots:
            source = ua.NodeId(snapshot.tag, self.ns)
            emitting = [_SERVER]
            tag_folder = parent_folder(aspace, source)
            if tag_folder is not None:
                emitting.append(tag_folder)
                if tag_folder not in self.notifiers:  # the tag's folder becomes an event notifier of the Server's
                    self.notifiers.append(tag_folder)
                    aspace[tag_folder].attributes[ua.AttributeIds.EventNotifier] = attribute_value(1, ua.VariantType.Byte)
                    link(server, aspace[tag_folder], _I.HasNotifier, None)
                link(aspace[tag_folder], aspace[source], _I.HasEventSource, None)
            event_class, type_id = _EVENT_CLASSES.get(snapshot.kind, (event_objects.AlarmCondition, _I.AlarmConditionType))
            node_id = ua.NodeId(f"alarms.{snapshot.name}", self.ns)
            node = make_node(aspace, node_id, ua.QualifiedName(snapshot.name, self.ns), snapshot.description or snapshot.name)
            link(folder, node, _I.Organizes, ua.NodeId(type_id))
            if source in aspace:
                link(aspace[source], node, _I.HasCondition, None)
            shelving_id = ua.NodeId(f"alarms.{snapshot.name}/ShelvingState", self.ns)
            shelving = make_node(aspace, shelving_id, ua.QualifiedName("ShelvingState", 0), "shelving of " + snapshot.name)
            link(node, shelving, _I.HasComponent, ua.NodeId(_I.ShelvedStateMachineType))
            for method in _CONDITION_METHODS:
                link(node, aspace[ua.NodeId(method)], _I.HasComponent, None, inverse=False)
            for method in _SHELVING_METHODS:
                link(shelving, aspace[ua.NodeId(method)], _I.HasComponent, None, inverse=False)
            event = new_event(event_class, node_id, source, snapshot)
            event.EventType = EventTypeId.of(aspace, type_id)
            condition = _Condition(snapshot.name, node_id, shelving_id, source, emitting, event)
            self.by_node[node_id] = self.by_node[shelving_id] = self.by_name[snapshot.name] = condition

    def _bind_methods(self) -> None:
        aspace = self.server.iserver.aspace
        bindings = {
            _I.AcknowledgeableConditionType_Acknowledge: self._acknowledge,
            _I.AcknowledgeableConditionType_Confirm: self._confirm,
            _I.ConditionType_AddComment: self._add_comment,
            _I.ConditionType_Enable: self._in_service, _I.AlarmConditionType_PlaceInService: self._in_service,
            _I.ConditionType_Disable: self._out_of_service, _I.AlarmConditionType_RemoveFromService: self._out_of_service,
            _I.ShelvedStateMachineType_TimedShelve: self._timed_shelve, _I.AlarmConditionType_ShelvingState_TimedShelve: self._timed_shelve,
            _I.ShelvedStateMachineType_TimedShelve2: self._timed_shelve,
            _I.ShelvedStateMachineType_OneShotShelve: self._one_shot_shelve, _I.AlarmConditionType_ShelvingState_OneShotShelve: self._one_shot_shelve,
            _I.ShelvedStateMachineType_OneShotShelve2: self._one_shot_shelve,
            _I.ShelvedStateMachineType_Unshelve: self._unshelve, _I.AlarmConditionType_ShelvingState_Unshelve: self._unshelve,
            _I.ShelvedStateMachineType_Unshelve2: self._unshelve,
            _I.ConditionType_ConditionRefresh: self._condition_refresh, _I.ConditionType_ConditionRefresh2: self._condition_refresh2,
        }
        for method, handler in bindings.items():
            aspace.add_method_callback(ua.NodeId(method), handler)
        # Refresh start/end events, as asyncua makes them for its own (unused here) refresh.
        self._refresh_events = (event_objects.RefreshStartEvent(), event_objects.RefreshEndEvent())
        for event in self._refresh_events:
            fix_types(event)
            event.SourceNode, event.SourceName, event.Severity = _SERVER, "Server", 1
            event.Message = ua.LocalizedText("ConditionRefresh")
            event.LocalTime = ua.TimeZoneDataType()

    # -- methods --------------------------------------------------------------------------

    async def _act(self, parent: ua.NodeId, command: str, arguments: dict[str, Any], event_id: Any = None) -> Any:
        origin = current_origin()
        condition = self.by_node.get(parent)
        if origin is None:
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        if condition is None:
            return ua.StatusCode(ua.StatusCodes.BadNodeIdInvalid)
        if event_id is not None and bytes(event_id or b"") not in condition.event_ids:
            return ua.StatusCode(ua.StatusCodes.BadEventIdUnknown)
        status, _, refusal = await call_command(self.plant.commands, command, {"alarm": condition.name, **arguments}, origin)
        if status is not None:
            return status
        if refusal is not None:
            code = next((code for kind, code in _REFUSALS.items() if isinstance(refusal, kind)), ua.StatusCodes.BadInvalidState)
            if isinstance(refusal, ServiceUnchanged):
                code = ua.StatusCodes.BadConditionAlreadyDisabled if command == "alarms.out_of_service" else ua.StatusCodes.BadConditionAlreadyEnabled
            return ua.StatusCode(code)
        return []

    async def _acknowledge(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        if len(values) < 2:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        return await self._act(parent, "alarms.acknowledge", {"comment": _text(values[1])}, event_id=values[0])

    async def _add_comment(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        if len(values) < 2:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        return await self._act(parent, "alarms.comment", {"comment": _text(values[1])}, event_id=values[0])

    async def _confirm(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        return ua.StatusCode(ua.StatusCodes.BadNotSupported)  # ConfirmedState is not part of softplc's model

    async def _timed_shelve(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        if not values or not isinstance(values[0], (int, float)):
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing if not values else ua.StatusCodes.BadTypeMismatch)
        if values[0] <= 0:
            return ua.StatusCode(ua.StatusCodes.BadShelvingTimeOutOfRange)
        reason = _text(values[1]) if len(values) > 1 else ""
        return await self._act(parent, "alarms.shelve", {"duration": float(values[0]) / 1000.0, "reason": reason or "TimedShelve over OPC UA"})

    async def _one_shot_shelve(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        reason = _text(values[0]) if values else ""
        return await self._act(parent, "alarms.shelve", {"one_shot": True, "reason": reason or "OneShotShelve over OPC UA"})

    async def _unshelve(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        return await self._act(parent, "alarms.unshelve", {"reason": _text(values[0]) if values else ""})

    async def _out_of_service(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        return await self._act(parent, "alarms.out_of_service", {"reason": (_text(values[0]) if values else "") or "Disable over OPC UA"})

    async def _in_service(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        return await self._act(parent, "alarms.in_service", {"reason": _text(values[0]) if values else ""})

    async def _condition_refresh(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        if not values:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        return await self._refresh(values[0], None)

    async def _condition_refresh2(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        values = _values(arguments)
        if len(values) < 2:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        return await self._refresh(values[0], values[1])

    async def _refresh(self, subscription_id: Any, monitored_item: Any) -> Any:
        """Replay the current state of every retained condition to one of the caller's subscriptions."""
        subscription = self.server.iserver.subscription_service.subscriptions.get(subscription_id)
        if subscription is None or subscription.session_id != current_session_id():
            return ua.StatusCode(ua.StatusCodes.BadSubscriptionIdInvalid)
        items = subscription.monitored_item_srv
        if monitored_item is not None and monitored_item not in items._monitored_items:
            return ua.StatusCode(ua.StatusCodes.BadMonitoredItemIdInvalid)
        start, end = self._refresh_events
        delivery = self.delivery
        assert delivery is not None
        await self._send_marker(items, start, monitored_item)
        targets = list(delivery.targets_of(subscription, monitored_item))
        for condition in list(self.by_name.values()):
            if condition.retained and condition.latest is not None:
                fill(condition, self.shelve_max)
                for node, target in targets:
                    if node in condition.emitting:
                        condition.event.emitting_node = node
                        await delivery.offer(condition, target)
        await self._send_marker(items, end, monitored_item)
        return []

    async def _send_marker(self, items: Any, marker: Any, monitored_item: Any) -> None:
        marker.EventId = uuid.uuid4().bytes
        marker.Time = marker.ReceiveTime = datetime.now(timezone.utc)
        for node in self.notifiers:
            marker.emitting_node = node
            await items.trigger_event(marker, monitored_item)


class AlarmSnapshotView:
    """The few fields of an `alarms.list` item the address space is built from."""

    def __init__(self, item: dict[str, Any]) -> None:
        self.name: str = item["name"]
        self.kind: str = item["kind"]
        self.tag: str = item["tag"]
        self.description: str = item.get("description", "")


def _values(arguments: tuple[ua.Variant, ...]) -> list[Any]:
    return [getattr(argument, "Value", argument) for argument in arguments]


def _text(value: Any) -> str:
    if isinstance(value, ua.LocalizedText):
        return value.Text or ""
    return "" if value is None else str(value)
