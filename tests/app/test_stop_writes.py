"""A write a client was told was accepted is never lost by a stop: `softplc run` as a real process,
written by real clients (asyncua over OPC UA, pymodbus FC16 over Modbus TCP), stopped by a real
signal the moment both writes are acknowledged, several times over; the retained values saved
last are the ones written."""

from __future__ import annotations

import asyncio
import re
import signal
import sqlite3
from pathlib import Path

from asyncua import Client, ua
from conftest import REPO
from opcua_support import PASSWORDS, add_users
from pymodbus.client import AsyncModbusTcpClient

from tests.app.test_cli import Process

CORE = REPO / "tests" / "core_programs.py"

# A slow task: a write journaled just before the signal waits up to a second for the next cycle,
# so a stop that does not apply the journal itself loses it nearly every time.
PLANT = f"""
version: 1
tags:
  from_modbus: {{type: int32, retain: true}}
  from_opcua: {{type: int32, retain: true}}
  ticks: {{type: uint32}}
tasks:
  slow:
    interval: 1s
    programs:
      - {{name: count, program: "{CORE}:Counter", bind: {{count: ticks}}}}
"""
STOPS = 4  # SIGTERM, SIGINT, SIGTERM, SIGINT


def retained(state_dir: Path) -> dict[str, int]:
    connection = sqlite3.connect(state_dir / "retain.sqlite")
    try:
        return {name: int(value) for name, value in connection.execute("SELECT name, value FROM retain")}
    finally:
        connection.close()


async def write_then_signal(endpoint: str, modbus_port: int, value: int, process: Process, signum: int) -> None:
    """Write `value` over both protocols, wait for both acknowledgements, and signal at once."""
    opcua = Client(endpoint, timeout=10)
    opcua.set_user("operator")
    opcua.set_password(PASSWORDS["operator"])
    modbus = AsyncModbusTcpClient("127.0.0.1", port=modbus_port, timeout=10)
    await opcua.connect()
    try:
        assert await modbus.connect()
        node = opcua.get_node("ns=2;s=from_opcua")
        words = [(value >> 16) & 0xFFFF, value & 0xFFFF]  # int32, big word order: holding 0-1
        answer = await modbus.write_registers(0, words, device_id=1)  # FC16
        assert not answer.isError(), answer
        await node.write_value(ua.DataValue(ua.Variant(value + 1, ua.VariantType.Int32)))  # raises unless Good
        process.popen.send_signal(signum)
    finally:
        modbus.close()
        try:
            await opcua.disconnect()
        except Exception:  # noqa: BLE001 — the server is stopping: its goodbye may not come
            pass


def test_writes_acknowledged_just_before_a_stop_signal_are_applied_and_retained(tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(PLANT)
    state_dir = tmp_path / "state"
    state_dir.mkdir()
    add_users(state_dir)
    for stop in range(STOPS):
        signum = signal.SIGTERM if stop % 2 == 0 else signal.SIGINT
        value = 1000 * (stop + 1)
        process = Process(["run", str(plant), "--no-status", "--state-dir", str(state_dir), "--no-hmi",
                           "--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--modbus-port", "0"], tmp_path)
        try:
            process.wait_for("press Ctrl-C to stop", timeout=60)
            output = "\n".join(process.lines)
            endpoint = re.search(r"serving: OPC UA on (opc\.tcp://\S+?/softplc/)", output)
            port = re.search(r"serving: Modbus TCP on 127\.0\.0\.1:(\d+)", output)
            assert endpoint and port, output
            asyncio.run(write_then_signal(endpoint.group(1), int(port.group(1)), value, process, signum))
            code = process.finish(timeout=60)
        finally:
            process.kill()
        output = "\n".join(process.lines)
        assert code == 0, output
        assert "Traceback" not in output
        assert retained(state_dir) == {"from_modbus": value, "from_opcua": value + 1}, f"stop {stop + 1} ({signal.Signals(signum).name})\n{output}"
