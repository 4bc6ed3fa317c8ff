"""A plant recording history on the simulated clock with its OPC UA server: deterministic values to read back.

On a 1 s task from 2026-01-01T00:00:00Z (simulated), the historian records every change of
    level     (float64, sloped)  t at each second t = 0..40, then nothing more (it holds 40)
    steps     (int32, stepped)   t // 3: 0 at 0 s, 1 at 3 s, ... 13 at 39 s
    pressure  (float64, sloped)  written by a driver: 0 good at 0 s, 10 good at 10 s, 5 BAD at 20 s,
                                 30 good at 30 s, 20 UNCERTAIN at 40 s, 50 good at 50 s
    note      (string, stepped)  "" at 0 s, never written
and `spare` is not recorded. The run goes on (faster than real time) while tests read.
"""

from __future__ import annotations

import argparse
import asyncio
import textwrap
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from softplc.core.tagdb import Origin
from softplc.core.tags import Quality
from tests.conftest import REPO
from tests.opcua_support import add_users

EPOCH = 1_767_225_600.0  # the simulated clock's wall time at 0 s
SUPPORT = REPO / "tests" / "history_support.py"
PRESSURE = [(0, 0.0, Quality.GOOD), (10, 10.0, Quality.GOOD), (20, 5.0, Quality.BAD), (30, 30.0, Quality.GOOD),
            (40, 20.0, Quality.UNCERTAIN), (50, 50.0, Quality.GOOD)]
RECORDED_UNTIL = 60.0  # simulated seconds run before the fixture hands the plant over

PLANT = f"""
version: 1
plant: {{name: history-plant}}
tags:
  level:    {{type: float64, unit: m, history: true}}
  steps:    {{type: int32, history: true}}
  pressure: {{type: float64, min: 0, max: 100, unit: bar, history: true}}
  note:     {{type: string, history: true}}
  spare:    {{type: float64}}
tasks:
  main:
    interval: 1s
    programs:
      - {{name: ramp, program: "{SUPPORT}:Ramp", bind: {{level: level, steps: steps}}}}
servers:
  opcua: {{security: [None]}}
  modbus: {{enabled: false}}
history: {{flush_period: 100ms}}
"""


@asynccontextmanager
async def recorded_plant(directory: Path, speed: float = 40.0) -> AsyncIterator[tuple[Runtime, Any]]:
    """The plant above as `softplc run --sim` builds it (historian, OPC UA on a free port), after 60 simulated seconds."""
    path = directory / "tagdb.yaml"
    path.write_text(textwrap.dedent(PLANT))
    config = load_config(path)
    state_dir = directory / "state"
    state_dir.mkdir(exist_ok=True)
    add_users(state_dir)
    clock = SimClock(speed=speed)  # simulated time, paced so the loop is not spinning while clients talk
    runtime = Runtime(config, clock, state_dir=state_dir, retain=False)
    for adapter in build_adapters(config, argparse.Namespace(sim=True)):
        runtime.add_adapter(adapter)
    await runtime.start()
    try:
        driver = Origin("driver", role=None)
        for second, value, quality in PRESSURE[1:]:
            await clock.sleep_until(second - 0.5)  # applied at the next cycle boundary: `second`
            runtime.db.submit([("pressure", value)], driver, quality=quality)
        await clock.sleep_until(RECORDED_UNTIL)
        recorder = next(a for a in runtime.adapters if a.name == "history")
        assert await asyncio.to_thread(recorder.flush), "the history writer did not commit"
        server = next(a for a in runtime.adapters if a.name == "opcua")
        yield runtime, server
    finally:
        await runtime.stop()
