"""Shared pieces of the links tests: a plant with links (real clock), remotes nobody here wrote, waiting on conditions.

The remotes are pymodbus's own `ModbusTcpServer` with a `SimDevice` (`PymodbusRemote`), asyncua's
own `Server` (`AsyncuaRemote`), and a second softplc in its own process (`SoftplcRemote`), all
on free loopback ports.
"""

from __future__ import annotations

import asyncio
import collections
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType as SimType
from pymodbus.simulator import SimData, SimDevice

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock

NO_SERVERS = """
servers:
  opcua: {enabled: false}
  modbus: {enabled: false}
  hmi: {enabled: false}
"""


async def wait_until(condition: Callable[[], bool], timeout: float = 5.0, what: str = "condition") -> float:
    """Poll `condition` every 2 ms until it holds; returns the seconds it took; fails after `timeout`."""
    started = time.monotonic()
    while not condition():
        if time.monotonic() - started > timeout:
            raise AssertionError(f"{what} not met within {timeout} s")
        await asyncio.sleep(0.002)
    return time.monotonic() - started


async def start_plant(tmp_path: Path, text: str, *, servers: str = NO_SERVERS, name: str = "tagdb.yaml") -> Runtime:
    """A runtime on the real clock, from YAML (with a 10 ms task so writes are applied), with the adapters its file asks for."""
    path = tmp_path / name
    body = textwrap.dedent(text)
    if "tasks:" not in body:
        body += "\ntasks:\n  main: {interval: 10ms}\n"
    path.write_text(body + textwrap.dedent(servers))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / f"state-{path.stem}")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    return runtime


def links_of(runtime: Runtime) -> Any:
    return next(adapter for adapter in runtime.adapters if adapter.name == "links")


class PymodbusRemote:
    """pymodbus's own Modbus TCP server (a SimDevice) on a free loopback port.

    `holding` / `inputs` are the register values it serves (addresses 0..size-1), changed by the
    test or by clients' writes; `requests` counts the requests by function code; `exceptions`
    maps a holding register's address to the exception code to answer any request of the holding
    registers touching it (FC3, FC6, FC16); while `hold` is
    clear, answers wait (a remote that stopped answering without closing the connection).
    """

    def __init__(self, size: int = 2000) -> None:
        self.size = size
        self.holding = [0] * size
        self.inputs = [0] * size
        self.requests: collections.Counter[int] = collections.Counter()
        self.request_log: list[tuple[int, int, int]] = []  # (function, address, count)
        self.exceptions: dict[int, ExcCodes] = {}
        self.hold = asyncio.Event()
        self.hold.set()
        self.server: ModbusTcpServer | None = None
        self.port = 0

    async def start(self, port: int = 0) -> None:
        device = SimDevice(
            1,
            simdata=(
                [SimData(0, values=[False] * 64, datatype=SimType.BITS)],
                [SimData(0, values=[False] * 64, datatype=SimType.BITS)],
                [SimData(0, values=[0] * self.size, datatype=SimType.REGISTERS)],
                [SimData(0, values=[0] * self.size, datatype=SimType.REGISTERS)],
            ),
            action=self._action,
        )
        self.server = ModbusTcpServer(device, address=("127.0.0.1", port))
        await self.server.serve_forever(background=True)
        sockets = getattr(self.server.transport, "sockets", None) or []
        self.port = sockets[0].getsockname()[1] if sockets else port

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.shutdown()
            self.server = None

    async def _action(self, function: int, start: int, address: int, count: int, registers: list[int], values: Any) -> ExcCodes | None:
        self.requests[function] += 1
        self.request_log.append((function, address, count))
        await self.hold.wait()
        if function in (3, 6, 16):
            for touched in range(address, address + count):
                if touched in self.exceptions:
                    return self.exceptions[touched]
        table = {3: self.holding, 6: self.holding, 16: self.holding, 4: self.inputs}.get(function)
        if table is None:
            return None  # coils and discrete inputs: pymodbus keeps them
        if values is not None:  # a write: it goes into our model, and pymodbus's block
            for offset, value in enumerate(values):
                table[address + offset] = int(value)
            return None
        for offset in range(count):  # a read: serve our model
            registers[address - start + offset] = table[address + offset]
        return None
