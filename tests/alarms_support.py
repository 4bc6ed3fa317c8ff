"""Helpers for the alarm tests: a small plant with alarms, run on the simulated clock from a script."""

from __future__ import annotations

import textwrap
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock, SimClock
from softplc.core.commands import CommandRefused
from softplc.core.events import Event
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality

EPOCH = 1_767_225_600.0  # SimClock's wall-clock origin
DRIVER = Origin("test-driver", role=None)
PEOPLE = {role.value: Origin("test", user=role.value, role=role) for role in Role}

PLANT = """
version: 1
plant: {name: alarm-test}
templates:
  task:
    instances: [t01, t02]
    tags:
      iBL: {type: float32, unit: "%", min: 0, max: 100}
tags:
  level:    {type: float64, unit: m}
  pressure: {type: float64, unit: bar, initial: 50}
  navstate: {type: string, initial: idle}
  running:  {type: bool, initial: true}
  counter:  {type: uint32}
  flag:     {type: bool}
tasks:
  scan:
    interval: 100ms
"""


def plant(alarms: str, head: str = PLANT) -> str:
    """The test plant with `alarms` (YAML of the alarms: section's body, any indentation)."""
    return textwrap.dedent(head) + "alarms:\n" + textwrap.indent(textwrap.dedent(alarms).strip("\n"), "  ") + "\n"


@dataclass(frozen=True)
class Step:
    """At simulated time `at`: write `tag` = `value` (as a driver), set its quality, or call a command as `role`."""

    at: float
    tag: str = ""
    value: Any = None
    quality: Quality | None = None
    command: str = ""
    arguments: dict[str, Any] | None = None
    role: str = ""  # a write: "" is a driver inside the runtime, else a client of that role


def write(at: float, tag: str, value: Any) -> Step:
    return Step(at, tag=tag, value=value)


def client_write(at: float, tag: str, value: Any, role: str) -> Step:
    return Step(at, tag=tag, value=value, role=role)


def bad(at: float, tag: str) -> Step:
    return Step(at, tag=tag, quality=Quality.BAD)


def good(at: float, tag: str) -> Step:
    return Step(at, tag=tag, quality=Quality.GOOD)


def call(at: float, command: str, role: str = "operator", **arguments: Any) -> Step:
    """A command, as an operator unless `role` says otherwise."""
    return Step(at, command=command, arguments=arguments, role=role)


@dataclass
class Run:
    runtime: Runtime
    events: list[Event]
    results: list[tuple[float, str, Any]]  # (time, command, result or the refusal's text)

    def transitions(self, alarm: str | None = None) -> list[tuple[float, str, str]]:
        """(time, transition, state after) of each event, times in simulated seconds."""
        return [(round(event.time - EPOCH, 3), event.data["transition"], event.data["alarm"].state.value)
                for event in self.events if alarm is None or event.source == alarm]


async def simulate(directory: Path, text: str, steps: Sequence[Step], duration: float) -> Run:
    """Run the plant on the simulated clock for `duration` s, doing each step at its time."""
    path = directory / "tagdb.yaml"
    path.write_text(text)
    config = load_config(path)
    clock = SimClock()
    runtime = Runtime(config, clock, state_dir=directory / "state", retain=False)
    for adapter in build_adapters(config, None):
        if adapter.name == "alarms":
            runtime.add_adapter(adapter)
    events: list[Event] = []
    results: list[tuple[float, str, Any]] = []
    runtime.events.subscribe(events.append, kinds=("alarm",))

    async def script() -> None:
        await runtime.running.wait()
        for step in sorted(steps, key=lambda step: step.at):
            await clock.sleep_until(step.at)
            if step.command:
                try:
                    result: Any = await runtime.commands.call(step.command, step.arguments or {}, PEOPLE[step.role])
                except CommandRefused as refused:
                    result = f"refused: {refused}"
                results.append((round(clock.now(), 3), step.command, result))
            elif step.quality is not None:
                runtime.db.submit_quality([step.tag], step.quality, DRIVER)
            else:
                refused = runtime.db.submit([(step.tag, step.value)], PEOPLE[step.role] if step.role else DRIVER)[0]
                results.append((round(clock.now(), 3), f"write {step.tag}", refused))

    runtime.spawn(script(), "script")
    await runtime.run(duration=duration)
    return Run(runtime, events, results)


@asynccontextmanager
async def running_alarm_plant(directory: Path, text: str, *, modbus: bool = False) -> AsyncIterator[tuple[Runtime, Any]]:
    """The plant in real time with its alarms and an OPC UA server on a free loopback port (users of every role)."""
    from softplc.adapters.opcua import OpcUaServer, OpcUaSettings
    from tests.opcua_support import add_users

    path = directory / "tagdb.yaml"
    path.write_text(text)
    config = load_config(path)
    state_dir = directory / "state"
    state_dir.mkdir(exist_ok=True)
    if not (state_dir / "users.yaml").exists():
        add_users(state_dir)
    runtime = Runtime(config, RealClock(), state_dir=state_dir)
    for adapter in build_adapters(config, None):
        if adapter.name == "alarms":
            runtime.add_adapter(adapter)
    server = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/"))
    runtime.add_adapter(server)
    await runtime.start()
    try:
        yield runtime, server
    finally:
        await runtime.stop()
