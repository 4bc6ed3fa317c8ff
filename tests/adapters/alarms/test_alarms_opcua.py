"""Alarms over OPC UA with asyncua: condition events, Acknowledge and shelving by role, ConditionRefresh,
and the Objects/Commands door."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from typing import Any

import pytest
from asyncua import Client, ua
from asyncua.ua.uaerrors import UaStatusCodeError

from tests.alarms_support import DRIVER, plant, running_alarm_plant
from tests.opcua_support import PASSWORDS

ALARMS = """
shelve_max: 1h
definitions:
  - {name: level_hi, limit: {tag: level, hi: 90, hihi: 95}, priority: high, message: "level {value:.0f} m ({level})"}
  - {name: nav_failed, discrete: {tag: navstate, value: failed}, priority: critical}
"""
I = ua.ObjectIds


class Events:
    """A subscription handler keeping every event's fields as a plain dict."""

    def __init__(self) -> None:
        self.seen: list[dict[str, Any]] = []

    def event_notification(self, event: Any) -> None:
        self.seen.append({name: variant.Value for name, variant in event.get_event_props_as_fields_dict().items()})

    async def wait_for(self, match: Callable[[dict[str, Any]], bool], timeout: float = 5.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            for fields in self.seen:
                if match(fields):
                    return fields
            assert time.monotonic() < deadline, f"no such event within {timeout} s; seen: {[f.get('ConditionName') for f in self.seen]}"
            await asyncio.sleep(0.01)


def client(server: Any, user: str) -> Client:
    connection = Client(server.endpoint, timeout=4)
    connection.set_user(user)
    connection.set_password(PASSWORDS[user])
    return connection


async def subscribe(connection: Client, node: Any, types: tuple[int, ...] = (I.AlarmConditionType,)) -> tuple[Any, Events]:
    events = Events()
    subscription = await connection.create_subscription(10, events)
    await subscription.subscribe_events(node, [connection.get_node(ua.NodeId(type_id)) for type_id in types])
    return subscription, events


def condition_of(server: Any, name: str) -> ua.NodeId:
    return ua.NodeId(f"alarms.{name}", server.namespace_index)


async def status_of(call: Any) -> str:
    try:
        await call
    except UaStatusCodeError as error:
        return type(error).__name__
    return "Good"


async def test_events_on_the_server_object_and_the_tag_folder_carry_the_condition_fields(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        async with client(server, "viewer") as connection:
            _, on_server = await subscribe(connection, connection.nodes.server, (I.AlarmConditionType, I.LimitAlarmType))
            folder = await connection.get_node(ua.NodeId("level", server.namespace_index)).get_parent()
            assert (await folder.read_event_notifier()) == {ua.EventNotifier.SubscribeToEvents}
            _, on_folder = await subscribe(connection, folder)
            runtime.db.submit([("level", 96.0)], DRIVER)
            fields = await on_server.wait_for(lambda f: f["ConditionName"] == "level_hi")
            assert fields["SourceName"] == "level" and fields["SourceNode"] == ua.NodeId("level", server.namespace_index)
            assert fields["Severity"] == 700 and fields["Message"].Text == "level 96 m (hihi)"
            assert fields["ActiveState/Id"] is True and fields["AckedState/Id"] is False and fields["Retain"] is True
            assert fields["ActiveState"].Text == "Active HighHigh" and fields["HighHighLimit"] == 95.0 and fields["HighLimit"] == 90.0
            assert fields["NodeId"] == condition_of(server, "level_hi") and fields["EventType"] == ua.NodeId(I.LimitAlarmType)
            assert fields["ShelvingState/CurrentState"].Text == "Unshelved" and fields["SuppressedOrShelved"] is False
            assert fields["MaxTimeShelved"] == 3_600_000.0 and isinstance(fields["EventId"], bytes) and fields["Time"] is not None
            assert (await on_folder.wait_for(lambda f: f["ConditionName"] == "level_hi"))["EventId"] == fields["EventId"]
            runtime.db.submit([("navstate", "failed")], DRIVER)
            assert (await on_server.wait_for(lambda f: f["ConditionName"] == "nav_failed"))["EventType"] == ua.NodeId(I.OffNormalAlarmType)


async def test_acknowledge_is_refused_for_a_viewer_and_done_for_an_operator(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        async with client(server, "operator") as operator, client(server, "viewer") as viewer:
            _, events = await subscribe(operator, operator.nodes.server)
            runtime.db.submit([("level", 92.0)], DRIVER)
            active = await events.wait_for(lambda f: f["ConditionName"] == "level_hi" and f["ActiveState/Id"])
            acknowledge = ua.NodeId(I.AcknowledgeableConditionType_Acknowledge)
            event_id = ua.Variant(active["EventId"], ua.VariantType.ByteString)
            comment = ua.LocalizedText("on my way")

            def ack(connection: Client, identifier: ua.Variant = event_id) -> Any:
                return connection.get_node(condition_of(server, "level_hi")).call_method(acknowledge, identifier, comment)

            assert await status_of(ack(viewer)) == "BadUserAccessDenied"
            assert await status_of(ack(operator, ua.Variant(b"not-an-event", ua.VariantType.ByteString))) == "BadEventIdUnknown"
            assert await status_of(ack(operator)) == "Good"
            acked = await events.wait_for(lambda f: f["ConditionName"] == "level_hi" and f["AckedState/Id"])
            assert acked["ClientUserId"] == "operator" and acked["Comment"].Text == "on my way" and acked["Retain"] is True
            assert await status_of(ack(operator)) == "BadConditionBranchAlreadyAcked"
            rows = await runtime.commands.call("alarms.journal", {"transition": "acknowledged"}, DRIVER)
            assert [(row["user"], row["comment"], row["origin"].split("@")[0]) for row in rows] == [("operator", "on my way", "opcua:operator")]


async def test_shelving_and_out_of_service_methods_by_role(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        async with client(server, "operator") as operator, client(server, "viewer") as viewer, client(server, "engineer") as engineer:
            _, events = await subscribe(operator, operator.nodes.server)
            runtime.db.submit([("level", 92.0)], DRIVER)
            await events.wait_for(lambda f: f["ConditionName"] == "level_hi")
            shelving = ua.NodeId("alarms.level_hi/ShelvingState", server.namespace_index)

            def timed(connection: Client, milliseconds: float) -> Any:
                return connection.get_node(shelving).call_method(ua.NodeId(I.ShelvedStateMachineType_TimedShelve), ua.Variant(milliseconds, ua.VariantType.Double))

            def unshelve(connection: Client) -> Any:
                return connection.get_node(shelving).call_method(ua.NodeId(I.ShelvedStateMachineType_Unshelve))

            assert await status_of(timed(viewer, 60_000)) == "BadUserAccessDenied"
            assert await status_of(timed(operator, 2 * 3_600_000)) == "BadShelvingTimeOutOfRange"
            assert await status_of(timed(operator, 60_000)) == "Good"
            shelved = await events.wait_for(lambda f: f["ShelvingState/CurrentState"].Text == "TimedShelved")
            assert shelved["SuppressedOrShelved"] is True and 0 < shelved["ShelvingState/UnshelveTime"] <= 60_000
            assert await _eventually(lambda: runtime.db.value("_sys.alarms.shelved") == 1)
            assert await status_of(unshelve(operator)) == "Good"
            assert await status_of(unshelve(operator)) == "BadConditionNotShelved"
            disable = ua.NodeId(I.ConditionType_Disable)
            node = operator.get_node(condition_of(server, "level_hi"))
            assert await status_of(node.call_method(disable)) == "BadUserAccessDenied"  # out of service is an engineer's
            assert await status_of(engineer.get_node(condition_of(server, "level_hi")).call_method(disable)) == "Good"
            disabled = await events.wait_for(lambda f: f["EnabledState/Id"] is False)
            assert disabled["OutOfServiceState/Id"] is True and disabled["ClientUserId"] == "engineer"
            assert await status_of(engineer.get_node(condition_of(server, "level_hi")).call_method(disable)) == "BadConditionAlreadyDisabled"
            confirm = node.call_method(ua.NodeId(I.AcknowledgeableConditionType_Confirm), ua.Variant(b"x", ua.VariantType.ByteString), ua.LocalizedText(""))
            assert await status_of(confirm) == "BadNotSupported"


async def _eventually(condition: Callable[[], bool], timeout: float = 3.0) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        await asyncio.sleep(0.01)
    return True


async def test_condition_refresh_shows_a_late_client_what_is_active(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        runtime.db.submit([("level", 92.0), ("navstate", "failed")], DRIVER)
        assert await _eventually(lambda: runtime.db.value("_sys.alarms.active") == 2)
        async with client(server, "viewer") as late, client(server, "operator") as other:
            subscription, events = await subscribe(late, late.nodes.server)
            other_subscription, _ = await subscribe(other, other.nodes.server)
            await asyncio.sleep(0.2)
            assert not events.seen  # nothing happened since it subscribed
            refresh = ua.NodeId(I.ConditionType_ConditionRefresh)
            condition_type = late.get_node(ua.NodeId(I.ConditionType))
            foreign = ua.Variant(other_subscription.subscription_id, ua.VariantType.UInt32)
            assert await status_of(condition_type.call_method(refresh, foreign)) == "BadSubscriptionIdInvalid"
            await condition_type.call_method(refresh, ua.Variant(subscription.subscription_id, ua.VariantType.UInt32))
            await events.wait_for(lambda f: f.get("ConditionName") == "nav_failed")
            names = sorted(f["ConditionName"] for f in events.seen if f.get("ConditionName"))
            assert names == ["level_hi", "nav_failed"]
            assert all(f["Retain"] and f["ActiveState/Id"] for f in events.seen if f.get("ConditionName"))


async def test_the_commands_door_checks_the_role_and_answers_json(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        runtime.db.submit([("level", 92.0)], DRIVER)
        assert await _eventually(lambda: runtime.db.value("_sys.alarms.unacknowledged") == 1)
        ns = server.namespace_index
        async with client(server, "viewer") as viewer, client(server, "operator") as operator:
            def call(connection: Client, name: str, arguments: Any) -> Any:
                text = arguments if isinstance(arguments, str) else json.dumps(arguments)
                return connection.get_node(ua.NodeId("Commands", ns)).call_method(ua.NodeId("Commands.Call", ns), name, text)

            listed = json.loads(await call(viewer, "alarms.list", {"state": "unacknowledged"}))
            assert listed["ok"] and [alarm["name"] for alarm in listed["result"]] == ["level_hi"]
            assert await status_of(call(viewer, "alarms.acknowledge", {"alarm": "level_hi"})) == "BadUserAccessDenied"
            assert await status_of(call(operator, "alarms.acknowledge", "[1, 2]")) == "BadInvalidArgument"
            assert json.loads(await call(operator, "alarms.acknowledge", {"alarm": "level_hj"})) == {
                "ok": False, "error": "no alarm named 'level_hj' (did you mean 'level_hi'?)"}
            assert json.loads(await call(operator, "alarms.acknowledge", {"alarm": "level_hi"}))["result"] == "acknowledged level_hi (now acknowledged)"
            listing = json.loads(await viewer.get_node(ua.NodeId("Commands", ns)).call_method(ua.NodeId("Commands.List", ns)))
            assert {"name": "alarms.shelve", "permission": "acknowledge"}.items() <= next(c for c in listing if c["name"] == "alarms.shelve").items()
            with pytest.raises(UaStatusCodeError, match="BadUserAccessDenied"):
                await viewer.get_node(ua.NodeId("_sys.alarms.acknowledge_all", ns)).write_value(True)
