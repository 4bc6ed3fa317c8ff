"""Online change (programs.apply) on the simulated clock: code and parameters swapped at a scan
boundary with the state carried over; broken or restart-needing changes refused, nothing applied."""

from __future__ import annotations

import sys
import textwrap
import uuid
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import Clock, SimClock
from softplc.core.commands import CommandRefused
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.engine.online_change.change import ChangeRefused

ENGINEER = Origin("cli", "erin", "127.0.0.1", role=Role.ENGINEER)

V1 = '''
from softplc import R_TRIG, InOut, Input, Output, Param, Program


class Mixer(Program):
    part = Input("photo eye")
    scans = InOut("scans")
    version = Output("code version")
    level = Output("gain times scans")
    gain = Param(1.0, "gain")

    def setup(self):
        self.count = 0
        self.times = []
        self.edge = R_TRIG()
        self.edges = 0
        self.note = None

    def scan(self):
        self.count += 1
        self.times.append(self.now)
        if self.edge(CLK=self.part):
            self.edges += 1
        self.scans += 1
        self.version = 1
        self.level = self.gain * self.count
'''

PLANT = """
version: 1
tags:
  part: {type: bool, initial: true}
  scans: {type: uint32}
  version: {type: uint16}
  level: {type: float64}
  n: {type: uint32}
tasks:
  fast:
    interval: 10ms
    programs:
      - name: mix
        program: MODULE:Mixer
        bind: {part: part, scans: scans, version: version, level: level}
        params: {gain: 1.0}
  slow:
    interval: 100ms
    programs:
      - {name: count, program: "CORE:Counter", bind: {count: n}}
""".replace("CORE", str(REPO / "tests" / "core_programs.py"))


class Plant:
    """A plant in a folder of its own, with its program module, running on the simulated clock (by default)."""

    def __init__(self, folder: Path, clock: Clock | None = None) -> None:
        self.module = f"oc_{uuid.uuid4().hex[:10]}"  # a fresh name: sys.modules outlives a test
        self.file = folder / f"{self.module}.py"
        self.config = folder / "tagdb.yaml"
        self.write_module(V1)
        self.write_config(PLANT)
        self.runtime = Runtime(load_config(self.config), clock or SimClock(), state_dir=folder / "state")
        self.calls: list[Any] = []
        self.runtime.commands.on_call(self.calls.append)

    def write_module(self, text: str) -> None:
        self.file.write_text(textwrap.dedent(text))

    def write_config(self, text: str) -> None:
        self.config.write_text(text.replace("MODULE", self.module))

    def edit(self, old: str, new: str, *, config: bool = False) -> None:
        file = self.config if config else self.file
        text = file.read_text()
        assert old in text, old
        file.write_text(text.replace(old, new))

    async def apply(self, origin: Origin = ENGINEER, **arguments: Any) -> Any:
        return await self.runtime.commands.call("programs.apply", arguments, origin)

    def value(self, name: str) -> Any:
        return self.runtime.db.value(name)

    def program_at(self) -> str:
        """Where the program `mix` is named in the file (FILE:LINE:COL of its `program:` value)."""
        line = next(i for i, text in enumerate(self.config.read_text().splitlines(), 1) if f"program: {self.module}:Mixer" in text)
        return f"{self.config}:{line}:18"


@pytest.fixture
async def plant(tmp_path: Path) -> Any:
    plant = Plant(tmp_path)
    await plant.runtime.start()
    yield plant
    await plant.runtime.stop()


async def test_new_code_is_swapped_in_at_a_scan_boundary_with_its_state_carried_over(plant: Plant) -> None:
    runtime, clock = plant.runtime, plant.runtime.clock
    await clock.sleep_until(0.105)
    old = runtime.program("mix")
    assert plant.value("version") == 1 and old.program.count == 11
    plant.edit("self.version = 1", "self.version = 2")  # same size, same second: no stale bytecode may be used
    result = await plant.apply()
    assert result["applied"] is True and result["changes"] == [f"program mix: code of {plant.module} changed"]
    (entry,) = result["programs"]
    assert entry["name"] == "mix" and entry["new_program"] is True and entry["state"] == "RUNNING"
    assert sorted(entry["carried_over"]) == ["count", "edge", "edges", "note", "times"]
    await clock.sleep_until(0.205)
    mix = runtime.program("mix")
    assert mix is not old and mix.version == 2 and plant.value("version") == 2
    assert type(mix.program) is not type(old.program)  # the new class, from the fresh module
    assert sys.modules[plant.module].Mixer is type(mix.program)
    # every cycle of the task scanned the program exactly once, across the swap
    task = runtime.tasks[0]
    assert mix.program.count == task.stats.cycles == 21 and task.stats.overruns == 0
    times = mix.program.times
    assert len(times) == 21 and all(b - a == pytest.approx(0.01) for a, b in zip(times, times[1:]))
    assert plant.value("scans") == 21 and plant.value("level") == 21.0
    assert mix.program.edges == 1  # the carried edge detector remembered the part: no false edge
    assert plant.value("_sys.fast.mix.state") == "RUNNING"
    listing = {p["name"]: p for p in await runtime.commands.call("programs.list", {}, ENGINEER)}
    assert listing["mix"]["version"] == 2 and listing["count"]["version"] == 1
    (call,) = plant.calls
    assert (call.command, call.accepted, call.detail) == ("programs.apply", True, "online change 1 applied: mix")


async def test_a_parameter_change_is_applied_and_the_state_carried_over(plant: Plant) -> None:
    runtime, clock = plant.runtime, plant.runtime.clock
    await clock.sleep_until(0.095)
    assert plant.value("level") == 10.0
    plant.edit("params: {gain: 1.0}", "params: {gain: 2.5}", config=True)
    result = await plant.apply()
    assert result["changes"] == ["program mix: params: gain 1.0 → 2.5"]
    await clock.sleep_until(0.105)
    assert plant.value("level") == 2.5 * 11  # the count went on; the new gain applies
    assert runtime.program("mix").params == {"gain": 2.5}


async def test_a_broken_module_is_refused_with_its_location_and_nothing_is_applied(plant: Plant) -> None:
    runtime, clock = plant.runtime, plant.runtime.clock
    await clock.sleep_until(0.05)
    old, config = runtime.program("mix"), runtime.config
    plant.edit("self.version = 1", "self.version = = 2")
    with pytest.raises(ChangeRefused) as refused:
        await plant.apply()
    message = str(refused.value)
    assert message.startswith("online change refused, nothing applied: 1 problem:\n")
    # where the code is broken, as PATH:LINE:COL (the whole path: the runtime may run elsewhere)
    line = next(number for number, text in enumerate(plant.file.read_text().splitlines(), 1) if "= = 2" in text)
    column = plant.file.read_text().splitlines()[line - 1].index("= = 2") + 3
    assert f"  {plant.program_at()}: cannot load program '{plant.module}:Mixer': {plant.file.resolve()}:{line}:{column}: SyntaxError: invalid syntax" in message
    assert refused.value.details["problems"] and refused.value.details["applied"] is False
    await clock.sleep_until(0.1)
    assert runtime.program("mix") is old and runtime.config is config and plant.value("version") == 1
    assert old.program.count == 10  # it kept scanning, untouched
    assert (plant.calls[-1].accepted, plant.calls[-1].detail) == (False, message)
    plant.edit("self.version = = 2", "self.version = 2")  # fixed: now it applies
    assert (await plant.apply())["applied"] is True


async def test_a_module_raising_at_import_is_refused_with_the_line_that_raised(plant: Plant) -> None:
    plant.edit("class Mixer(Program):", "GAIN = undefined_name\n\n\nclass Mixer(Program):")
    with pytest.raises(ChangeRefused, match=rf"NameError: name 'undefined_name' is not defined at {plant.file}:5"):
        await plant.apply()
    assert plant.runtime.program("mix").version == 1


async def test_a_bad_binding_is_a_located_problem(plant: Plant) -> None:
    plant.edit("level: level}", "level: lvl}", config=True)
    with pytest.raises(ChangeRefused, match=r"tagdb.yaml:\d+:\d+: 'level' of program 'mix' is bound to a missing tag 'lvl' \(did you mean 'level'\?\)"):
        await plant.apply()


async def test_a_new_version_whose_setup_raises_is_refused(plant: Plant) -> None:
    plant.edit("        self.count = 0\n", "        self.count = 0\n        raise RuntimeError('no calibration')\n")
    with pytest.raises(ChangeRefused) as refused:
        await plant.apply()
    assert (f"{plant.program_at()}: the new version of program 'mix' cannot start: RuntimeError: no calibration at {plant.file}:"
            in str(refused.value))
    assert plant.runtime.program("mix").program.count > 0 and plant.runtime.program("mix").version == 1


async def test_changes_that_need_a_restart_are_refused_with_the_reasons_and_the_diff(plant: Plant) -> None:
    runtime = plant.runtime
    plant.edit("  n: {type: uint32}\n", "  n: {type: uint32}\n  extra: {type: bool}\n", config=True)
    plant.edit("  version: {type: uint16}", "  version: {type: uint32}", config=True)
    plant.edit("interval: 100ms", "interval: 200ms", config=True)
    plant.edit("params: {gain: 1.0}", "params: {gain: 3.0}", config=True)
    with pytest.raises(ChangeRefused) as refused:
        await plant.apply()
    assert str(refused.value) == "\n".join([
        "online change refused, nothing applied: changes that need a restart of the runtime:",
        "  tag 'extra' added",
        "  tag 'version': type 'uint16' → 'uint32'",
        "  task 'slow': interval 100ms → 200ms",
        "the other differences (not applied):",
        "  program mix: params: gain 1.0 → 3.0",
    ])
    assert refused.value.details["needs_restart"][0] == "tag 'extra' added"
    assert runtime.program("mix").params == {"gain": 1.0}


async def test_check_shows_the_differences_and_applies_nothing(plant: Plant) -> None:
    plant.edit("self.version = 1", "self.version = 3")
    result = await plant.apply(check=True)
    assert result == {"file": str(plant.config), "applied": False, "changes": [f"program mix: code of {plant.module} changed"],
                      "needs_restart": [], "problems": [], "summary": f"checked, not applied ({plant.config})"}
    await plant.runtime.clock.sleep_until(0.05)
    assert plant.value("version") == 1


async def test_an_unchanged_file_applies_nothing(plant: Plant) -> None:
    result = await plant.apply()
    assert result["applied"] is False and result["changes"] == []
    assert result["summary"] == f"nothing to apply: the running programs match the file ({plant.config})"


async def test_only_an_engineer_may_apply(plant: Plant) -> None:
    plant.edit("self.version = 1", "self.version = 2")
    for role in (Role.VIEWER, Role.OPERATOR):
        with pytest.raises(CommandRefused, match=f"role {role.value} may not apply online changes"):
            await plant.apply(Origin("opcua", "someone", role=role))
    assert plant.runtime.program("mix").version == 1


async def test_on_fault_restart_and_enabled_change_in_place(plant: Plant) -> None:
    runtime, clock = plant.runtime, plant.runtime.clock
    await clock.sleep_until(0.05)
    mix = runtime.program("mix")
    plant.edit("        params: {gain: 1.0}\n", "        params: {gain: 1.0}\n        on_fault: initial\n"
               "        restart: {delay: 1s, max: 2}\n        enabled: false\n", config=True)
    result = await plant.apply()
    assert result["programs"][0]["changes"] == ["on_fault: hold → initial", "restart: never → {'delay': 1.0, 'max': 2}",
                                                "enabled: true → false"]
    assert runtime.program("mix") is mix and mix.state.value == "STOPPED" and mix.version == 2
    assert plant.value("version") == 0 and plant.value("level") == 0.0  # stopped: its reaction, initial
    assert plant.value("_sys.fast.mix.state") == "STOPPED"
    plant.edit("        enabled: false\n", "", config=True)
    await plant.apply()  # enabled again: a new program object, set up warm
    await clock.sleep_until(0.1)
    assert runtime.program("mix").state.value == "RUNNING" and plant.value("version") == 1


async def test_a_class_may_convert_its_state_in_carry_over(plant: Plant) -> None:
    await plant.runtime.clock.sleep_until(0.05)
    plant.edit("    def scan(self):\n        self.count", "    def carry_over(self, old):\n        self.count = 1000 + old.count\n"
               "        return ['count']\n\n    def scan(self):\n        self.count")
    result = await plant.apply()
    assert result["programs"][0]["carried_over"] == ["count"]
    await plant.runtime.clock.sleep_until(0.065)
    assert plant.runtime.program("mix").program.count == 1000 + 6 + 1
    assert plant.runtime.program("mix").program.edges == 0  # not carried: a new R_TRIG, created warm in setup()
