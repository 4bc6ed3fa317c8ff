"""The OPC UA latency client's path from a pushed Ready to its answer, against our runtime over loopback."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.core.clock import RealClock
from softplc.core.roles import Role
from softplc.latency.client import HandshakeClient
from softplc.latency.driver import DriverError
from softplc.latency.opcua_driver import DEFAULT_NODE_IDS, OpcuaDriver
from softplc.latency.plant import handshake_config
from softplc.security.users import UserStore

PASSWORD = "handshake-test-password"


async def _runtime(tmp_path: Path) -> tuple[Runtime, Any]:
    UserStore(tmp_path / "users.yaml").add("tester", Role.OPERATOR, PASSWORD)
    config = handshake_config("fast", 0.01, opcua_endpoint="opc.tcp://127.0.0.1:0/softplc/")
    runtime = Runtime(config, RealClock(), state_dir=tmp_path)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    return runtime, next(adapter for adapter in runtime.adapters if adapter.name == "opcua")


async def test_the_answer_reaches_the_server_before_the_next_publish_request(tmp_path):
    """The Write answering a pushed Ready is served with none of the client's Publish requests
    waiting in front of it: the client sends its next Publish request only after the Write."""
    runtime, server = await _runtime(tmp_path)
    waiting_at_answer: list[int] = []

    def on_write(events: Any) -> None:
        # Called while the server serves the client's Write: count the Publish requests it holds.
        if any(event.tag == "TaskID" for event in events):
            waiting_at_answer.append(sum(len(protocol.processor._publish_requests) for protocol in server.server.bserver.clients))

    unsubscribe = runtime.db.on_write(on_write)
    driver = OpcuaDriver(server.endpoint, DEFAULT_NODE_IDS, user="tester", password=PASSWORD, timeout=30.0)
    events: list[dict[str, Any]] = []
    try:
        await driver.connect()
        try:
            await HandshakeClient(driver, events.append, samples=6, duration=None, timeout=10.0).run()
        finally:
            await driver.close()
    finally:
        unsubscribe()
        await runtime.stop()
    samples = [event for event in events if event["type"] == "sample"]
    assert len(samples) == 6 and all(sample["status"] == "ok" for sample in samples)
    # The first answer (the warm-up) may answer a Ready read before the wait began; every timed one
    # answers a push.
    assert len(waiting_at_answer) == 7
    assert waiting_at_answer[1:] == [0] * 6


async def test_ready_is_seen_when_its_publish_response_arrives(tmp_path):
    """t_seen is taken as asyncua's publish loop hands over the PublishResult, before the answer."""
    runtime, server = await _runtime(tmp_path)
    driver = OpcuaDriver(server.endpoint, DEFAULT_NODE_IDS, user="tester", password=PASSWORD, timeout=30.0)
    events: list[dict[str, Any]] = []
    try:
        await driver.connect()
        try:
            await HandshakeClient(driver, events.append, samples=4, duration=None, timeout=10.0).run()
        finally:
            await driver.close()
    finally:
        await runtime.stop()
    samples = [event for event in events if event["type"] == "sample"]
    assert len(samples) == 4
    for sample in samples:
        assert sample["ready_stamp"] < sample["t_seen"] <= sample["t_sent"] < sample["t_done"]


async def test_a_plc_that_never_sets_ready_ends_the_run_with_what_the_subscription_saw(tmp_path):
    """Three timeouts in a row end the run; the message says what was last pushed, and when."""
    from softplc.config import parse_config

    UserStore(tmp_path / "users.yaml").add("tester", Role.OPERATOR, PASSWORD)
    config = parse_config("""version: 1
plant: {name: idle}
tags:
  Ready: {type: bool}
  TaskID: {type: uint16}
servers:
  opcua: {enabled: true, endpoint: "opc.tcp://127.0.0.1:0/softplc/"}
  modbus: {enabled: false}
  hmi: {enabled: false}
""", tmp_path / "idle.yaml")
    runtime = Runtime(config, RealClock(), state_dir=tmp_path)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    server = next(adapter for adapter in runtime.adapters if adapter.name == "opcua")
    driver = OpcuaDriver(server.endpoint, {"ready": "ns={ns};s=Ready", "task_id": "ns={ns};s=TaskID"}, user="tester", password=PASSWORD, timeout=30.0)
    events: list[dict[str, Any]] = []
    try:
        await driver.connect()
        try:
            with pytest.raises(DriverError) as ended:
                await HandshakeClient(driver, events.append, samples=2, duration=None, timeout=0.3).run()
        finally:
            await driver.close()
    finally:
        await runtime.stop()
    assert [event["type"] for event in events] == ["hello", "timeout", "timeout", "timeout"]
    message = str(ended.value)
    assert "3 times in a row" in message and "no new Ready pushed within 0.3 s" in message
    assert "last PublishResponse" in message and "s ago; Ready low as last pushed" in message
