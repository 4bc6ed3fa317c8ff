"""Two `softplc run` processes forming a pair on loopback, a real etcd, a TCP proxy on the sync link, and an
output device that records every output with its epoch (shared by the fault tests and bench/redundancy_failover.py)."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.adapters.redundancy.pair_support import free_port, write_pair

REPO = Path(__file__).resolve().parents[3]
PASSWORD = "pair-secret"

OUTPUT_PROGRAM = """
      - name: output
        program: tests.adapters.redundancy.pair_programs:EpochOutput
        bind: {{scans: scans}}
        params: {{port: {port}}}
"""
SERVERS = """
servers:
  modbus: {enabled: false}
  hmi: {enabled: false}
"""


@dataclass
class Output:
    member: str
    epoch: int
    scans: int
    sent: float  # CLOCK_MONOTONIC when the runtime sent it (one clock for every process here)
    received: float


@dataclass
class OutputDevice:
    """A UDP device every output goes to: it records them in arrival order (a thread: the test's loop may block)."""

    port: int = 0
    outputs: list[Output] = field(default_factory=list)
    names: dict[int, str] = field(default_factory=dict)  # process id → member name

    def start(self) -> None:
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.bind(("127.0.0.1", 0))
        self._socket.settimeout(0.2)
        self.port = self._socket.getsockname()[1]
        self._running = True
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while self._running:
            try:
                data = self._socket.recv(200)
            except OSError:
                continue
            pid, epoch, scans, sent = data.decode().split()
            self.outputs.append(Output(self.names.get(int(pid), pid), int(epoch), int(scans), float(sent), time.monotonic()))

    def stop(self) -> None:
        self._running = False
        self._thread.join(timeout=2)
        self._socket.close()

    def overlaps(self) -> list[tuple[Output, Output]]:
        """Outputs that arrived after an output of a newer epoch: two actives at once (must be none)."""
        found = []
        newest: Output | None = None
        for output in list(self.outputs):
            if newest is not None and output.epoch < newest.epoch:
                found.append((newest, output))
            if newest is None or output.epoch > newest.epoch:
                newest = output
        return found

    def last(self, member: str | None = None) -> Output | None:
        chosen = [output for output in list(self.outputs) if member is None or output.member == member]
        return chosen[-1] if chosen else None


class Proxy:
    """A TCP proxy on the sync link that can cut it (drop every connection and refuse new ones) and restore it."""

    def __init__(self, target: int) -> None:
        self.target = target
        self.port = free_port()
        self.cut = False
        self._server: asyncio.AbstractServer | None = None
        self._streams: list[asyncio.StreamWriter] = []
        self._handlers: set[asyncio.Task[Any]] = set()

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", self.port)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._handlers.add(task)
            task.add_done_callback(self._handlers.discard)
        if self.cut:
            writer.close()
            return
        try:
            upstream_reader, upstream_writer = await asyncio.open_connection("127.0.0.1", self.target)
        except OSError:
            writer.close()
            return
        self._streams += [writer, upstream_writer]

        async def pump(source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
            try:
                while not self.cut:
                    data = await source.read(65536)
                    if not data:
                        break
                    sink.write(data)
            except (OSError, ConnectionError):
                pass
            finally:
                sink.close()

        await asyncio.gather(pump(reader, upstream_writer), pump(upstream_reader, writer))

    def sever(self) -> None:
        self.cut = True
        for stream in self._streams:
            stream.close()
        self._streams.clear()

    def restore(self) -> None:
        self.cut = False

    async def stop(self) -> None:
        self.sever()
        if self._server is not None:
            self._server.close()
        await asyncio.gather(*self._handlers, return_exceptions=True)


class Member:
    """One `softplc run` process of the pair."""

    def __init__(self, name: str, config: Path, folder: Path, opcua_port: int, device: OutputDevice | None = None) -> None:
        self.name = name
        self.device = device
        self.config = config
        self.state = folder / f"state-{name}"
        self.opcua_port = opcua_port
        self.log = folder / f"{name}.log"
        self.process: subprocess.Popen[bytes] | None = None
        from softplc.core.roles import Role
        from softplc.security.users import UserStore

        self.state.mkdir(parents=True, exist_ok=True)
        UserStore(self.state / "users.yaml").add("olga", Role.OPERATOR, PASSWORD, log2_n=10)

    @property
    def endpoint(self) -> str:
        return f"opc.tcp://127.0.0.1:{self.opcua_port}/softplc/"

    def start(self) -> None:
        environment = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
        command = [sys.executable, "-m", "softplc", "run", str(self.config), "--redundancy-member", self.name,
                   "--state-dir", str(self.state), "--opcua-endpoint", self.endpoint, "--no-status", "--no-fleet"]
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, cwd=self.config.parent, env=environment)
        if self.device is not None:
            self.device.names[self.process.pid] = self.name

    def signal(self, number: int) -> None:
        assert self.process is not None
        self.process.send_signal(number)

    def kill(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGCONT)
            self.process.terminate()
            try:
                self.process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=10)

    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None


class Pair:
    """Two members of one plant with a real etcd (see the module docstring)."""

    def __init__(self, folder: Path, etcd: Any, *, interval: str = "10ms", proxy: bool = True) -> None:
        self.folder = folder
        self.etcd = etcd
        self.device = OutputDevice()
        self.device.start()
        listen_a = free_port()
        self.proxy = Proxy(listen_a) if proxy else None
        ports = {"sync_a": listen_a, "opcua_a_port": free_port(), "opcua_b_port": free_port()}
        ports["opcua_a_url"] = f"opc.tcp://127.0.0.1:{ports['opcua_a_port']}/softplc/"  # type: ignore[assignment]
        ports["opcua_b_url"] = f"opc.tcp://127.0.0.1:{ports['opcua_b_port']}/softplc/"  # type: ignore[assignment]
        # 1 s: the faults are judged against the takeover time of issue 25 (etcd tuned for it)
        self.config = write_pair(folder, etcd.endpoint, servers=SERVERS, interval=interval, lease="1s", ports=ports,
                                 proxies={"a": self.proxy.port} if self.proxy else None)
        text = self.config.read_text().replace("        bind: {part: part, scans: scans, edges: edges, done: done, draw: draw}\n",
                                               "        bind: {part: part, scans: scans, edges: edges, done: done, draw: draw}\n"
                                               + OUTPUT_PROGRAM.format(port=self.device.port).lstrip("\n"))
        self.config.write_text(text)
        self.members = {name: Member(name, self.config, folder, ports[f"opcua_{name}_port"], self.device) for name in "ab"}

    async def start(self) -> None:
        if self.proxy is not None:
            await self.proxy.start()
        for member in self.members.values():
            member.start()

    async def stop(self) -> None:
        for member in self.members.values():
            member.stop()
        if self.proxy is not None:
            await self.proxy.stop()
        self.device.stop()

    def logs(self) -> str:
        return "\n".join(f"--- {member.name} ---\n{member.log.read_text()[-3000:]}" for member in self.members.values() if member.log.exists())
