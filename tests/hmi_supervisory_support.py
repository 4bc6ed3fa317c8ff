"""Helpers of the supervisory HMI tests: a plant with alarms and history, its HMI, Modbus, users.

The runtime is built the way `softplc run` builds it (`build_adapters`: alarms and historian
before the HMI, which adds the alarm, journal and trend pages when their commands are there).
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

from hmi_support import Plant, add_users

from softplc.adapters.hmi.server import HmiServer
from softplc.adapters.hmi.settings import HmiSettings
from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock

PLANT = textwrap.dedent("""
    version: 1
    plant: {name: supervisory test plant}
    templates:
      task:
        group: Tasks
        instances: [t01, t02]
        tags:
          iBM: {type: uint16, unit: items, min: 0, max: 10000, description: input buffer items}
          iBL: {type: float32, unit: "%", min: 0, max: 100, access: ro, description: input buffer level}
          iBC: {type: uint16, initial: 100, unit: items, min: 1, max: 10000}
    tags:
      limit:   {type: float64, min: -1000, max: 1000, unit: bar, description: a bounded rw tag}
      flag:    {type: bool, description: a switch}
      speed:   {type: float64, unit: m/s, description: a second unit for the trend}
    tasks:
      plant:
        interval: 100ms
        programs:
          - name: level_{task}
            program: tests.hmi_support:Level
            for_each: task
            bind: {items: "{task}_iBM", capacity: "{task}_iBC", level: "{task}_iBL"}
    alarms:
      shelve_max: 8h
      definitions:
        - name: "{task}_input_full"
          for_each: task
          limit: {tag: "{task}_iBL", hi: {limit: 90, priority: high}, hihi: {limit: 100, priority: critical}, deadband: 10}
          message: "input buffer of {task} at {value:.0f} %: send a robot"
          description: "the task's input stops at 100 %"
        - name: flag_on
          discrete: {tag: flag, value: true}
          priority: low
          message: "the flag is on"
    history:
      flush_period: 0.2s
      record:
        - tags: ["t*_iBL", "t*_iBM", limit, flag, speed]
    servers:
      hmi: {host: 127.0.0.1, port: 0}
      modbus: {host: 127.0.0.1, port: 0}
      opcua: {enabled: false}
    """)


async def start_supervisory_plant(folder: Path, *, clock: Any = None, modbus: bool = True, text: str = PLANT, **settings: Any) -> Plant:
    """Write and start the plant (alarms, historian, Modbus on a free port, the HMI) with a user of every role."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "tagdb.yaml"
    path.write_text(text)
    state = folder / "state"
    add_users(state)
    config = load_config(path)
    runtime = Runtime(config, clock or RealClock(), state_dir=state, retain=False)
    adapters: dict[str, Any] = {}
    hmi: HmiServer | None = None
    for adapter in build_adapters(config, None):
        if adapter.name == "hmi":
            hmi = HmiServer(config, HmiSettings.from_config(config).override(**settings))
            adapter = hmi
        elif adapter.name == "modbus" and not modbus:
            continue
        adapters[adapter.name] = adapter
        runtime.add_adapter(adapter)
    assert hmi is not None
    await runtime.start()
    return Plant(runtime, hmi, adapters)
