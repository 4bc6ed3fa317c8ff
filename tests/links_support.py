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


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (for servers that cannot report the port they bound)."""
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class AsyncuaRemote:
    """asyncua's own `Server` (default settings) in this process on a free loopback port.

    `add(name, value, variant_type, writable)` adds a variable `ns=2;s=NAME` (in folders of 100:
    node insertion is O(siblings) in asyncua); `created` lists the sizes of the CreateMonitoredItems
    requests the server answered (one entry per request).
    """

    NAMESPACE = "urn:test:remote"

    def __init__(self) -> None:
        from asyncua import Server

        self.server = Server()
        self.port = free_port()
        self.endpoint = f"opc.tcp://127.0.0.1:{self.port}/remote/"
        self.created: list[int] = []
        self.index = 0
        self._folders: list[Any] = []
        self.nodes: dict[str, Any] = {}

    async def start(self) -> None:
        from asyncua.common.callback import CallbackType

        await self.server.init()
        self.server.set_endpoint(self.endpoint)
        self.index = await self.server.register_namespace(self.NAMESPACE)
        self.server.subscribe_server_callback(CallbackType.ItemSubscriptionCreated, self._created)
        await self.server.start()

    async def _created(self, event: Any, dispatcher: Any) -> None:
        self.created.append(len(event.request_params.ItemsToCreate))

    async def add(self, name: str, value: Any, variant_type: Any, writable: bool = False) -> Any:
        from asyncua import ua

        if not self._folders or len(self.nodes) >= 100 * len(self._folders):
            self._folders.append(await self.server.nodes.objects.add_folder(self.index, f"F{len(self._folders)}"))
        node = await self._folders[-1].add_variable(ua.NodeId(name, self.index), name, ua.Variant(value, variant_type))
        if writable:
            await node.set_writable()
        self.nodes[name] = node
        return node

    async def set(self, name: str, value: Any, variant_type: Any, status: Any = None) -> None:
        """Write a DataValue on the server side: any type, any status (a misbehaving remote)."""
        from asyncua import ua

        data_value = ua.DataValue(ua.Variant(value, variant_type))
        if status is not None:
            data_value.StatusCode = ua.StatusCode(status)
        await self.server.write_attribute_value(self.nodes[name].nodeid, data_value)

    async def retype(self, name: str, value: Any, variant_type: Any) -> None:
        """Change a node's DataType and value (a remote whose program was changed under the link)."""
        from asyncua import ua

        nodeid = self.nodes[name].nodeid
        await self.server.write_attribute_value(nodeid, ua.DataValue(ua.Variant(ua.NodeId(variant_type.value, 0))), ua.AttributeIds.DataType)
        await self.set(name, None, ua.VariantType.Null, ua.StatusCodes.BadWaitingForInitialData)  # a bad status nulls the value: the new DataType rules
        await self.set(name, value, variant_type)

    async def value(self, name: str) -> Any:
        return await self.nodes[name].read_value()

    async def stop(self) -> None:
        await self.server.stop()


class SoftplcRemote:
    """A second softplc: `softplc run FILE` in its own process, serving OPC UA and Modbus on free loopback ports.

    `yaml` is its plant (tags, tasks); the servers are added here. An operator `link` (password
    `PASSWORD`) may write over OPC UA. `stop(signal)` kills or freezes it; `start()` runs it again
    on the same ports and state.
    """

    PASSWORD = "link-password"

    def __init__(self, directory: Path, yaml: str) -> None:
        self.directory = directory
        self.opcua_port = free_port()
        self.modbus_port = free_port()
        self.endpoint = f"opc.tcp://127.0.0.1:{self.opcua_port}/softplc/"
        self.path = directory / "remote.yaml"
        self.path.write_text(textwrap.dedent(yaml) + textwrap.dedent(f"""
            servers:
              opcua: {{endpoint: "{self.endpoint}"}}
              modbus: {{host: 127.0.0.1, port: {self.modbus_port}}}
              hmi: {{enabled: false}}
            """))
        self.state = directory / "remote-state"
        from softplc.core.roles import Role
        from softplc.security.users import UserStore

        UserStore(self.state / "users.yaml").add("link", Role.OPERATOR, self.PASSWORD)
        (directory / "link.password").write_text(self.PASSWORD + "\n")
        self.process: asyncio.subprocess.Process | None = None
        self.output: list[str] = []

    async def start(self, timeout: float = 60.0) -> None:
        """Run it and wait until both servers serve."""
        import os
        import sys

        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
        self.process = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "softplc", "run", str(self.path), "--state-dir", str(self.state), "--no-status",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT, env=env,
        )
        assert self.process.stdout is not None
        serving = 0
        deadline = time.monotonic() + timeout
        while serving < 2:
            line = await asyncio.wait_for(self.process.stdout.readline(), max(0.1, deadline - time.monotonic()))
            if not line:
                raise AssertionError("the remote softplc ended:\n" + "".join(self.output[-30:]))
            text = line.decode(errors="replace")
            self.output.append(text)
            serving += text.startswith("serving:")
        self._drain = asyncio.ensure_future(self._read_rest())

    async def _read_rest(self) -> None:
        assert self.process is not None and self.process.stdout is not None
        while line := await self.process.stdout.readline():
            self.output.append(line.decode(errors="replace"))

    def signal(self, number: int) -> None:
        assert self.process is not None
        self.process.send_signal(number)

    async def kill(self) -> None:
        import signal

        if self.process is not None and self.process.returncode is None:
            self.process.send_signal(signal.SIGCONT)
            self.process.kill()
            await self.process.wait()
            await asyncio.gather(self._drain, return_exceptions=True)
