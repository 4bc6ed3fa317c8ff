"""Run a scenario on the simulated clock: plant programs, dispatcher, simulated robots, records.

    result = run_scenario(load_scenario("scenarios/case1-sim1.yaml"), Path("out"))

builds the scenario's plant (`softplc.scenarios.plant`), starts it on a `SimClock` with the
robots driven by the fleet's simulated driver, records every cycle, stops on the thesis's
termination condition (an output storage full) or the time limit, and writes the records,
figures, the plant it ran and a JSON summary into the output folder.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from softplc.app.runtime import Adapter, Runtime
from softplc.config import PlantConfig
from softplc.core.clock import SimClock
from softplc.scenarios.plant import build_plant
from softplc.scenarios.recorder import Recorder
from softplc.scenarios.spec import Scenario
from softplc.scenarios.summary import summarise

Progress = Callable[[float, str], None]
AdapterFactory = Callable[[Scenario, PlantConfig], Adapter]


@dataclass
class RunResult:
    """What a run produced: the summary, the files written, and the wall time it took."""

    scenario: Scenario
    summary: dict[str, Any]
    recorder: Recorder
    files: dict[str, Path] = field(default_factory=dict)
    wall_seconds: float = 0.0


def stop_condition(scenario: Scenario) -> str | None:
    """The `until` condition of the scenario's stop rule (None: only the time limit)."""
    full = [f"{task.id}_qSL >= 100" for task in scenario.tasks]
    if scenario.stop == "any_full":
        return " or ".join(full)
    if scenario.stop == "all_full":
        return " and ".join(full)
    return None


def _full_check(scenario: Scenario, runtime: Runtime) -> Callable[[], bool]:
    """The scenario's stop rule as a function of the output levels (checked after every cycle)."""
    tags = [runtime.db[f"{task.id}_qSL"] for task in scenario.tasks]
    if scenario.stop == "any_full":
        return lambda: any(tag.value >= 100.0 for tag in tags)
    if scenario.stop == "all_full":
        return lambda: all(tag.value >= 100.0 for tag in tags)
    return lambda: False


def run_scenario(
    scenario: Scenario,
    out_dir: Path | None = None,
    *,
    progress: Progress | None = None,
    figures: bool = True,
    time_limit: float | None = None,
    adapter_factory: AdapterFactory | None = None,
) -> RunResult:
    """Run `scenario` to its end and write its outputs into `out_dir` (nothing written if None)."""
    return asyncio.run(run_scenario_async(scenario, out_dir, progress=progress, figures=figures,
                                          time_limit=time_limit, adapter_factory=adapter_factory))


async def run_scenario_async(
    scenario: Scenario,
    out_dir: Path | None = None,
    *,
    progress: Progress | None = None,
    figures: bool = True,
    time_limit: float | None = None,
    adapter_factory: AdapterFactory | None = None,
) -> RunResult:
    started = time.monotonic()
    compatible = compatibility(scenario)
    config, plant_text = build_plant(scenario, compatible)
    limit = time_limit if time_limit is not None else scenario.time_limit
    state_dir = (out_dir or Path(".")) / ".state"
    runtime = Runtime(config, SimClock(), state_dir=state_dir)
    factory = adapter_factory or fleet_adapter
    runtime.add_adapter(factory(scenario, config))
    tasks = [task.id for task in scenario.tasks]
    recorder = Recorder(runtime.db, [robot.id for robot in scenario.robots], tasks,
                        every=scenario.record_every, svm=scenario.dispatcher == "svm")
    full = _full_check(scenario, runtime)

    def after_cycle(task: object) -> None:
        recorder.observe(runtime.clock.now())
        if full():
            runtime.request_stop(f"condition met: {stop_condition(scenario)}")
        if progress is not None:
            _report(progress, runtime, scenario, limit)

    runtime.engine.after_cycle(after_cycle)
    reason = await runtime.run(duration=limit)
    duration = runtime.clock.now()
    if not recorder.xy or float(recorder.xy[-1][0]) < duration:
        recorder.sample(duration)  # the final state, whatever the sampling phase
    if progress is not None:
        _report(progress, runtime, scenario, limit, final=True)
    summary = summarise(scenario, runtime.db, recorder, duration, _reason(reason, scenario))
    result = RunResult(scenario, summary, recorder)
    if runtime.error:
        summary["runtime_error"] = runtime.error
    faulted = {i.name: i.error for t in runtime.tasks for i in t.programs if i.state.value == "FAULTED"}
    if faulted:
        summary["faulted_programs"] = faulted
    if out_dir is not None:
        result.files = write_outputs(result, out_dir, plant_text, figures)
    result.wall_seconds = time.monotonic() - started
    summary["wall_time_s"] = round(result.wall_seconds, 3)
    if out_dir is not None:
        _write_summary(result, out_dir)
    return result


def _reason(reason: str, scenario: Scenario) -> str:
    if reason.startswith("condition met"):
        return "an output storage is full" if scenario.stop == "any_full" else "every output storage is full"
    if reason.startswith("duration"):
        return "time limit reached"
    return reason or "stopped"


def _report(progress: Progress, runtime: Runtime, scenario: Scenario, limit: float, final: bool = False) -> None:
    now = runtime.clock.now()
    levels = [float(runtime.db.value(f"{task.id}_qSL")) for task in scenario.tasks]
    fraction = now / limit
    if scenario.stop == "any_full":
        fraction = max(fraction, max(levels) / 100.0)
    elif scenario.stop == "all_full":
        fraction = max(fraction, min(levels) / 100.0)
    outputs = " ".join(f"T{n}-out {level:3.0f}%" for n, level in enumerate(levels, 1))
    progress(1.0 if final else fraction, f"t={now:7.1f} s  {outputs}")


def write_outputs(result: RunResult, out_dir: Path, plant_text: str, figures: bool) -> dict[str, Path]:
    """Records, figures and the plant configuration; the summary is written last."""
    out_dir.mkdir(parents=True, exist_ok=True)
    name = result.scenario.name
    files = result.recorder.write(out_dir, name)
    plant_path = out_dir / f"plant_{name}.yaml"
    plant_path.write_text(plant_text)
    files["plant"] = plant_path
    if figures:
        from softplc.scenarios.figures import draw_figures
        from softplc.scenarios.fleet import factory_floor

        files.update(draw_figures(result.scenario, result.recorder, out_dir, factory_floor().grid))
    files["summary"] = out_dir / f"summary_{name}.json"
    return files


def _write_summary(result: RunResult, out_dir: Path) -> None:
    result.summary["files"] = {key: path.name for key, path in sorted(result.files.items())}
    result.files["summary"].write_text(json.dumps(result.summary, indent=2) + "\n")


def compatibility(scenario: Scenario) -> list[list[int]]:
    """Task numbers each robot may serve, from the fleet's compatibility check."""
    from softplc.scenarios.fleet import compatible_tasks

    return compatible_tasks(scenario)


def fleet_adapter(scenario: Scenario, config: PlantConfig) -> Adapter:
    """The fleet adapter driving the scenario's robots with the simulated driver."""
    from softplc.scenarios.fleet import build_fleet_adapter

    return build_fleet_adapter(scenario, config)
