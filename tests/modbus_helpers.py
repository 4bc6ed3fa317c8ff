"""Shared pieces of the Modbus tests: a running plant with the Modbus server on a free port."""

from __future__ import annotations

import asyncio
import re
import shutil
import struct
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient

from softplc.adapters.modbus.server import ModbusAdapter
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.program import Input, Output, Program


@dataclass
class ModbusPlant:
    """A runtime serving Modbus TCP on 127.0.0.1:port, with a connected pymodbus client."""

    runtime: Runtime
    adapter: ModbusAdapter
    client: AsyncModbusTcpClient

    @property
    def port(self) -> int:
        assert self.adapter.port is not None
        return self.adapter.port

    @property
    def db(self) -> Any:
        return self.runtime.db

    def address(self, tag: str) -> int:
        return self.adapter.map.by_tag[tag].address

    async def wait_for(self, condition: Callable[[], bool], timeout: float = 2.0) -> None:
        """Poll `condition` every 5 ms until it holds; fail after `timeout` seconds."""
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise AssertionError(f"condition not met within {timeout} s")
            await asyncio.sleep(0.005)

    async def next_cycles(self, count: int = 2) -> None:
        """Wait until `count` more scan cycles of the first task have run (journal applied)."""
        task = self.runtime.tasks[0]
        target = task.stats.cycles + count
        await self.wait_for(lambda: task.stats.cycles >= target)


async def start_plant(tmp_path: Path, yaml_text: str, **settings: Any) -> ModbusPlant:
    """Load YAML, start the runtime with the Modbus adapter on a free port, connect a client."""
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(yaml_text))
    config = load_config(path)
    base = ModbusSettings.from_servers(config.servers)
    adapter = ModbusAdapter(config, ModbusSettings(**{**base.__dict__, "enabled": True, "port": 0, **settings}))
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    runtime.add_adapter(adapter)
    await runtime.start()
    client = AsyncModbusTcpClient("127.0.0.1", port=adapter.port, timeout=2, retries=0)
    await client.connect()
    assert client.connected
    return ModbusPlant(runtime, adapter, client)


async def stop_plant(plant: ModbusPlant) -> None:
    plant.client.close()
    await plant.runtime.stop()


def words_of(fmt: str, value: Any, word_order: str = "big") -> list[int]:
    """Registers of a struct-packed value, written independently of softplc's codec."""
    data = struct.pack(">" + fmt, value)
    words = [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
    return words[::-1] if word_order == "little" else words


def value_of(fmt: str, words: list[int], word_order: str = "big") -> Any:
    ordered = words[::-1] if word_order == "little" else words
    return struct.unpack(">" + fmt, b"".join(w.to_bytes(2, "big") for w in ordered))[0]


async def raw_request(port: int, frame: bytes, timeout: float = 2.0) -> bytes:
    """Send one raw Modbus TCP frame and return the raw answer (for malformed requests)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(frame)
        await writer.drain()
        header = await asyncio.wait_for(reader.readexactly(6), timeout)
        length = int.from_bytes(header[4:6], "big")
        return header + await asyncio.wait_for(reader.readexactly(length), timeout)
    finally:
        writer.close()


def mbpoll_path() -> str:
    """The mbpoll executable (Debian package), or a failed test saying how to install it."""
    path = shutil.which("mbpoll")
    if path is None:
        pytest.fail("mbpoll is not installed: run scripts/install-test-tools.sh (apt-get install -y mbpoll)")
    return path


def polled(output: str) -> dict[int, str]:
    """mbpoll's '[ref]: value' lines."""
    return {int(ref): value for ref, value in re.findall(r"^\[(\d+)\]:\s+(\S+)", output, re.MULTILINE)}


def mbap(transaction: int, unit: int, pdu: bytes) -> bytes:
    """A Modbus TCP frame: MBAP header + PDU."""
    return transaction.to_bytes(2, "big") + b"\0\0" + (len(pdu) + 1).to_bytes(2, "big") + bytes([unit]) + pdu


# A plant with one 10 ms task whose program doubles a setpoint (the robustness and connection tests).
DOUBLER_PLANT = """
version: 1
tags:
  counter: {type: uint32, access: ro}
  setpoint: {type: float64}
  doubled: {type: float64, access: ro}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: doubler
        program: modbus_helpers:Doubler
        bind: {setpoint: setpoint, doubled: doubled, scans: counter}
servers:
  modbus: {}
"""


class Doubler(Program):
    """Test program: `doubled` = 2 × `setpoint` and `scans` counts scans, written every scan."""

    setpoint = Input("a value clients write")
    doubled = Output("2 x setpoint, written by the scan")
    scans = Output("scan counter")

    def scan(self) -> None:
        self.doubled = 2.0 * self.setpoint
        self.scans = (self.scans + 1) % 2**32
