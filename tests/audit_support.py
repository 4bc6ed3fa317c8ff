"""Helpers for the audit tests: a plant with every door open (OPC UA, Modbus, the HMI, alarms, programs), as `softplc run` builds it."""

from __future__ import annotations

import asyncio
import json
import os
import sys
import textwrap
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from asyncua import Client, ua

from softplc import InOut, Program
from softplc.adapters.audit.recorder import AuditRecorder
from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.storage.audit.entry import AuditEntry
from softplc.storage.audit.queries import AuditQuery
from tests.conftest import REPO
from tests.opcua_support import PASSWORDS, add_users

PLANT = """
version: 1
plant: {name: audit-test}
tags:
  level:    {type: float32, min: 0, max: 100, unit: "%"}
  setpoint: {type: int16, min: -100, max: 100}
  count:    {type: uint32, access: ro}
  name:     {type: string, initial: idle}
tasks:
  fast:
    interval: 10ms
    programs:
      - {name: ticker, program: "tests.audit_support:Ticker", bind: {count: count}}
servers:
  opcua: {endpoint: "opc.tcp://127.0.0.1:0/softplc/"}
  modbus: {port: 0}
  hmi: {port: 0}
alarms:
  definitions:
    - {name: level_hi, limit: {tag: level, hi: 90}, priority: high}
audit: {flush_period: 50ms}
"""


class Ticker(Program):
    """Counts its scans."""

    count = InOut("scan counter")

    def scan(self) -> None:
        self.count = (self.count + 1) % 2**32


@asynccontextmanager
async def running(directory: Path, text: str = PLANT, **flags: Any) -> AsyncIterator[Runtime]:
    """The plant on the real clock with every adapter `softplc run` would start (audit first), users added."""
    path = directory / "tagdb.yaml"
    path.write_text(textwrap.dedent(text))
    config = load_config(path)
    state = directory / "state"
    state.mkdir(exist_ok=True)
    add_users(state)
    runtime = Runtime(config, RealClock(), state_dir=state)
    import argparse

    for adapter in build_adapters(config, argparse.Namespace(**flags) if flags else None):
        runtime.add_adapter(adapter)
    await runtime.start()
    try:
        yield runtime
    finally:
        await runtime.stop()


def adapter(runtime: Runtime, name: str) -> Any:
    return next(item for item in runtime.adapters if item.name == name)


def recorder(runtime: Runtime) -> AuditRecorder:
    return adapter(runtime, "audit")


async def entries(runtime: Runtime, **query: Any) -> list[AuditEntry]:
    """The committed entries matching the query, oldest first."""
    audit = recorder(runtime)
    assert await asyncio.to_thread(audit.flush, 10.0)
    found = await asyncio.to_thread(audit.search, AuditQuery(**query))
    return list(reversed(found))


def opcua_client(runtime: Runtime, user: str | None = None) -> Client:
    client = Client(adapter(runtime, "opcua").endpoint, timeout=4)
    if user is not None:
        client.set_user(user)
        client.set_password(PASSWORDS[user])
    return client


def local_address(transport: Any) -> str:
    host, port = transport.get_extra_info("sockname")[:2]
    return f"{host}:{port}"


async def call_door(client: Client, name: str, arguments: dict[str, Any]) -> Any:
    """Call a runtime command through the OPC UA door (Objects/Commands.Call); its decoded reply, or the StatusCode's name."""
    ns = await client.get_namespace_index("urn:softplc:tags")
    door = client.get_node(ua.NodeId("Commands", ns))
    try:
        reply = await door.call_method(ua.NodeId("Commands.Call", ns), name, json.dumps(arguments))
    except ua.UaStatusCodeError as error:
        return ua.StatusCode(error.code).name
    return json.loads(reply)


async def softplc(*arguments: str, home: Path, password: str | None = None, timeout: float = 60) -> tuple[int, str, str]:
    """`softplc ARGUMENTS` in its own process; returns (exit status, stdout, stderr)."""
    env = dict(os.environ, PYTHONPATH=str(REPO), HOME=str(home))
    env.pop("SOFTPLC_PASSWORD", None)
    if password is not None:
        env["SOFTPLC_PASSWORD"] = password
    process = await asyncio.create_subprocess_exec(sys.executable, "-m", "softplc.app.cli", *arguments, env=env, stdin=asyncio.subprocess.DEVNULL,
                                                   stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    out, err = await asyncio.wait_for(process.communicate(), timeout)
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def wait_until(condition: Callable[[], bool], timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout} s")
        await asyncio.sleep(0.01)
