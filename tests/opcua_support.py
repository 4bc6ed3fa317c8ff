"""Helpers for the OPC UA tests: a small plant, users, a running server, client certificates, waiting."""

from __future__ import annotations

import asyncio
import textwrap
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from asyncua import Client

from softplc import InOut, Input, Output, Program
from softplc.adapters.opcua import OpcUaServer, OpcUaSettings, Role, UserStore
from softplc.adapters.opcua.history import HistoryProvider
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import Clock, RealClock
from softplc.protocols.opcua_client import ClientCertificate, ensure_client_certificate, pem_certificate

PASSWORDS = {"viewer": "viewer-pass-1", "operator": "operator-pass-1", "engineer": "engineer-pass-1"}
TEST_HASH_COST = 10  # log2 N of the tests' password hashes: milliseconds, not the default's ~0.4 s

PLANT = """
version: 1
plant: {name: opcua-test}
templates:
  robot:
    group: Robots
    instances: [r01, r02]
    tags:
      xpos:   {type: float64, unit: m, access: ro, description: x position}
      xgoal:  {type: float64, unit: m, min: 0, max: 21.95, description: x goal}
      status: {type: bool, description: busy}
tags:
  b1:      {type: bool}
  i16:     {type: int16, min: -100, max: 100, unit: "%", description: a bounded int16}
  u16:     {type: uint16}
  i32:     {type: int32}
  u32:     {type: uint32}
  f32:     {type: float32, min: 0, max: 10, unit: m/s}
  f64:     {type: float64}
  s1:      {type: string, initial: hello}
  ro_i32:  {type: int32, access: ro, initial: 7, description: read-only for clients}
  count:   {type: uint32, access: ro, description: scans of the fast task}
  request: {type: int32, description: written by clients}
  reply:   {type: int32, access: ro, description: the program's echo of request}
  ramp:    {type: float64, access: ro, min: 0, max: 1000, description: count modulo 1000}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: ticker
        program: tests.opcua_support:Ticker
        bind: {count: count, request: request, reply: reply, ramp: ramp}
"""


class Ticker(Program):
    """Counts scans, echoes `request` into `reply` (so a client write is seen by a program), and
    ramps `ramp` by 1 per scan over its EURange 0..1000 (a slow drift for deadband tests)."""

    count = InOut("scan counter")
    request = Input("client-written value")
    reply = Output("echo of request")
    ramp = Output("count modulo 1000")

    def scan(self) -> None:
        self.count = (self.count + 1) % 2**32
        self.reply = self.request
        self.ramp = float(self.count % 1000)


def write_config(directory: Path, text: str = PLANT) -> Path:
    path = directory / "tagdb.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def add_users(state_dir: Path) -> UserStore:
    store = UserStore(state_dir / "users.yaml")
    for role in Role:
        store.add(role.value, role, PASSWORDS[role.value], log2_n=TEST_HASH_COST)
    return store


@asynccontextmanager
async def running_plant(directory: Path, text: str = PLANT, *, clock: Clock | None = None, history: HistoryProvider | None = None,
                        **settings: Any) -> AsyncIterator[tuple[Runtime, OpcUaServer]]:
    """A runtime (real time unless `clock` says otherwise) with the OPC UA server on a free loopback port."""
    config = load_config(write_config(directory, text))
    state_dir = directory / "state"
    state_dir.mkdir(exist_ok=True)
    if not (state_dir / "users.yaml").exists():
        add_users(state_dir)
    settings.setdefault("endpoint", "opc.tcp://127.0.0.1:0/softplc/")
    server = OpcUaServer(OpcUaSettings(**settings), history=history)
    runtime = Runtime(config, clock or RealClock(), state_dir=state_dir)
    runtime.add_adapter(server)
    await runtime.start()
    try:
        yield runtime, server
    finally:
        await runtime.stop()


def client_for(server: OpcUaServer, user: str | None = None, password: str | None = None, timeout: float = 4) -> Client:
    client = Client(server.endpoint, timeout=timeout)
    if user is not None:
        client.set_user(user)
        client.set_password(password if password is not None else PASSWORDS[user])
    return client


async def wait_until(condition: Callable[[], Awaitable[bool] | bool], timeout: float = 5.0, interval: float = 0.01) -> None:
    """Poll `condition` every `interval` until it holds; fail after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if asyncio.iscoroutine(result):
            result = await result
        if result:
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout} s")
        await asyncio.sleep(interval)


def make_client_certificate(directory: Path, name: str = "test-client") -> ClientCertificate:
    """A self-signed OPC UA client certificate (DER + PEM key; also NAME.cert.pem for node-opcua)."""
    certificate = ensure_client_certificate(directory, name, days=30)
    (directory / f"{name}.cert.pem").write_bytes(pem_certificate(certificate))
    return certificate
