"""The MQTT connection every MQTT user shares (softplc/protocols/mqtt.py), against a real mosquitto."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from softplc.core.clock import RealClock
from softplc.protocols.mqtt import MqttConnection, NotConnected, Will
from softplc.protocols.mqtt_settings import MqttSettings


async def until(condition, timeout: float = 10.0, what: str = "condition") -> None:
    deadline = asyncio.get_running_loop().time() + timeout
    while not condition():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"{what} not met within {timeout} s")
        await asyncio.sleep(0.01)


async def test_messages_flow_the_will_fires_and_a_broker_restart_is_survived(mosquitto) -> None:
    settings = MqttSettings(port=mosquitto.port, keepalive=2)
    sender = MqttConnection(settings, "sender", RealClock(), will=lambda: Will("plant/will", b"gone", qos=1, retain=True))
    receiver = MqttConnection(settings, "receiver", RealClock(), max_backoff=1.0)
    received: list[tuple[str, bytes, bool]] = []
    states: list[bool] = []
    receiver.subscribe("plant/#", lambda topic, payload, retained: received.append((topic, payload, retained)), qos=1)
    receiver.on_state(states.append)
    with pytest.raises(NotConnected):
        await sender.publish("plant/early", b"x")
    tasks = [asyncio.create_task(sender.run()), asyncio.create_task(receiver.run())]
    try:
        await until(lambda: sender.connected and receiver.connected, what="both connected")
        await sender.publish("plant/hello", b"1", qos=1)
        await until(lambda: ("plant/hello", b"1", False) in received, what="hello received")
        mosquitto.stop()
        await until(lambda: not receiver.connected, what="the receiver notices the broker is gone")
        mosquitto.start()
        await until(lambda: sender.connected and receiver.connected, timeout=15, what="both reconnected")
        assert states[:3] == [True, False, True] and receiver.connects == 2
        await sender.publish("plant/again", b"2", qos=1)  # the receiver subscribed again by itself
        await until(lambda: ("plant/again", b"2", False) in received, what="a message after the restart")
        tasks[0].cancel()  # the sender dies without a goodbye: its will is published
        sender_socket = sender._client._client.socket()  # noqa: SLF001 - cut the line as a crash would
        sender_socket.close()
        await until(lambda: any(topic == "plant/will" for topic, _, _ in received), timeout=10, what="the will")
    finally:
        for task in tasks:
            task.cancel()
        await receiver.close()


async def test_an_oversized_message_is_dropped_and_counted(mosquitto) -> None:
    settings = MqttSettings(port=mosquitto.port)
    sender = MqttConnection(settings, "sender", RealClock())
    receiver = MqttConnection(settings, "receiver", RealClock(), max_payload=1000)
    received: list[bytes] = []
    receiver.subscribe("big/#", lambda topic, payload, retained: received.append(payload))
    tasks = [asyncio.create_task(sender.run()), asyncio.create_task(receiver.run())]
    try:
        await until(lambda: sender.connected and receiver.connected)
        await sender.publish("big/one", b"x" * 5000, qos=1)
        await sender.publish("big/two", b"small", qos=1)
        await until(lambda: received == [b"small"], what="only the small message")
        assert receiver.dropped == 1
    finally:
        for task in tasks:
            task.cancel()
        await sender.close()
        await receiver.close()


def test_the_settings_come_from_the_mqtt_section(make_config, tmp_path: Path) -> None:
    (tmp_path / "pw").write_text("secret\n")
    config = make_config("""
        version: 1
        plant: {name: line1}
        tags: {a: {type: float32}}
        mqtt: {url: "mqtts://broker.example:8884", username: plc, password_file: pw, keepalive: 20s, protocol: "3.1.1"}
    """)
    settings = MqttSettings.from_config(config)
    assert (settings.host, settings.port, settings.tls is not None, settings.keepalive, settings.protocol) == ("broker.example", 8884, True, 20.0, "3.1.1")
    assert settings.client_id == "softplc-line1" and settings.password() == "secret" and settings.url == "mqtts://broker.example:8884"


async def test_a_restart_reconnects_at_once_without_the_will_and_asks_for_a_new_one(mosquitto) -> None:
    settings = MqttSettings(port=mosquitto.port)
    wills: list[int] = []

    def will() -> Will:
        wills.append(len(wills))
        return Will("node/death", str(wills[-1]).encode(), qos=1)

    node = MqttConnection(settings, "node", RealClock(), will=will)
    watcher = MqttConnection(settings, "watcher", RealClock())
    seen: list[tuple[str, bytes]] = []
    states: list[bool] = []
    watcher.subscribe("node/#", lambda topic, payload, retained: seen.append((topic, payload)), qos=1)
    node.on_state(states.append)
    tasks = [asyncio.create_task(node.run()), asyncio.create_task(watcher.run())]
    try:
        await until(lambda: node.connected and watcher.connected, what="both connected")
        began = asyncio.get_running_loop().time()
        await node.restart("the primary host went offline")
        await until(lambda: node.connects == 2 and node.connected, what="the node connected again")
        assert asyncio.get_running_loop().time() - began < 1.0  # at once: no backoff
        assert states == [True, False, True] and wills == [0, 1]
        # The broker publishes a will as the old session ends, before it serves the new one: had
        # there been one, the watcher would see it before this message of the new session.
        await node.publish("node/alive", b"", qos=1)
        await until(lambda: ("node/alive", b"") in seen, what="the new session's message")
        assert seen == [("node/alive", b"")]  # a clean DISCONNECT: no will
    finally:
        for task in tasks:
            task.cancel()
        await node.close()
        await watcher.close()


async def test_mqtt_3_1_1_connects(mosquitto) -> None:
    """protocol: "3.1.1" (what the embedded broker speaks): paho refuses a clean_start flag outside MQTT 5."""
    connection = MqttConnection(MqttSettings(port=mosquitto.port, protocol="3.1.1"), "old", RealClock())
    received: list[bytes] = []
    connection.subscribe("old/#", lambda topic, payload, retained: received.append(payload))
    task = asyncio.create_task(connection.run())
    try:
        await until(lambda: connection.connected, what="connected with MQTT 3.1.1")
        await connection.publish("old/x", b"1", qos=1)
        await until(lambda: received == [b"1"], what="a message back")
    finally:
        task.cancel()
        await connection.close()
