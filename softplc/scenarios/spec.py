"""Scenario files: the parameters of one simulated experiment (`scenarios/*.yaml`).

A scenario names a dispatcher, the tasks (fill rates, supply-chain inputs, stations, what a
robot needs to serve them) and the robots (load capacity, start, what they are), plus how
the run ends. Mistakes are reported as `FILE:LINE:COL: message`, like `tagdb.yaml`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from softplc.config import did_you_mean, schema_problems
from softplc.config.schema import NAME_PATTERN
from softplc.config.yamlsource import ConfigError, SourceMap, load_yaml
from softplc.robotics.robots import HARDWARE_NAMES

PROJECT = Path(__file__).resolve().parent.parent.parent
BUILTIN_DIR = PROJECT / "scenarios"
DISPATCHERS = ("weighting", "cooperative", "svm", "optimal")
STOPS = ("any_full", "all_full", "time_limit")

# Keys of a robot or task entry that describe what it *is* (thesis Tables 6-7); they are
# handed to the fleet's compatibility check. The other keys are plant parameters.
ROBOT_SPEC_KEYS = ("name", "length_mm", "width_mm", "height_mm", "load_capacity", "max_linear_speed", "max_angular_speed", "hardware")
TASK_SPEC_KEYS = ("name", "max_length_mm", "max_width_mm", "max_height_mm", "min_load_capacity", "min_linear_speed",
                  "min_angular_speed", "max_team_size", "requires")

_NUMBER = {"type": "number"}
_NON_NEGATIVE = {"type": "number", "minimum": 0}
_POINT = {
    "type": "object",
    "properties": {"x": _NUMBER, "y": _NUMBER},
    "required": ["x", "y"],
    "additionalProperties": False,
}
_RANGE = {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 100}, "minItems": 2, "maxItems": 2,
          "description": "[low, high] in %"}

SCENARIO_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "scenario": {
            "type": "object",
            "properties": {
                "name": {"type": "string", "pattern": r"^[A-Za-z0-9_.-]+$"},
                "title": {"type": "string"},
                "thesis": {"type": "string", "description": "What the thesis reported for this experiment."},
                "stop": {"enum": list(STOPS), "description": "any_full: an output storage full (the thesis); all_full; time_limit."},
                "time_limit": {"type": "number", "exclusiveMinimum": 0, "description": "Simulated seconds at most."},
                "record_every": {"type": "number", "exclusiveMinimum": 0, "description": "Seconds between recorded samples."},
                "seed": {"type": "integer"},
            },
            "required": ["name"],
            "additionalProperties": False,
        },
        "plant": {
            "type": "object",
            "properties": {
                "handling_time": {"type": "number", "minimum": 0,
                                  "description": "Seconds a robot stands at a station to be loaded or unloaded."},
                "park_after": {"type": "number", "minimum": 0,
                               "description": "Seconds without a task before a robot drives back to its start (0: never)."},
            },
            "additionalProperties": False,
        },
        "dispatcher": {
            "type": "object",
            "properties": {
                "type": {"enum": list(DISPATCHERS)},
                "model": {"type": "string", "description": "svm: model JSON, relative to this file."},
                "interval": {"type": "number", "exclusiveMinimum": 0, "description": "Seconds between decisions (default 1)."},
                "skip_full": {"type": "boolean", "description": "Never send a robot to a full output storage (not the thesis)."},
            },
            "required": ["type"],
            "additionalProperties": False,
        },
        "tasks": {
            "type": "array",
            "minItems": 1,
            "items": {
                "type": "object",
                "properties": {
                    "id": {"type": "string", "pattern": NAME_PATTERN},
                    "iFr": {**_NON_NEGATIVE, "description": "input fill rate, items per minute"},
                    "iBC": {"type": "integer", "minimum": 1},
                    "qSC": {"type": "integer", "minimum": 1},
                    "iBM": {"type": "integer", "minimum": 0, "description": "items in the input buffer at the start"},
                    "sPPi": {"type": "number", "exclusiveMinimum": 0},
                    "sCDr": _NUMBER,
                    "demand": _RANGE,
                    "source": _POINT,
                    "destination": _POINT,
                    "name": {"type": "string"},
                    "max_length_mm": _NON_NEGATIVE, "max_width_mm": _NON_NEGATIVE, "max_height_mm": _NON_NEGATIVE,
                    "min_load_capacity": _NON_NEGATIVE, "min_linear_speed": _NON_NEGATIVE, "min_angular_speed": _NON_NEGATIVE,
                    "max_team_size": {"type": "integer", "minimum": 1},
                    "requires": {"type": "array", "items": {"enum": HARDWARE_NAMES}, "uniqueItems": True},
                },
                "required": ["id", "source", "destination"],
                "additionalProperties": False,
            },
        },
        "robots": {
            "type": "array",
            "minItems": 1,
            "items": {
                "type": "object",
                "properties": {
                    "id": {"type": "string", "pattern": NAME_PATTERN},
                    "loadcap": {"type": "integer", "minimum": 1, "description": "items the robot carries"},
                    "start": {**_POINT, "properties": {"x": _NUMBER, "y": _NUMBER, "heading": _NUMBER}},
                    "name": {"type": "string"},
                    "length_mm": _NON_NEGATIVE, "width_mm": _NON_NEGATIVE, "height_mm": _NON_NEGATIVE,
                    "load_capacity": _NON_NEGATIVE, "max_linear_speed": _NON_NEGATIVE, "max_angular_speed": _NON_NEGATIVE,
                    "hardware": {"type": "array", "items": {"enum": HARDWARE_NAMES}, "uniqueItems": True},
                },
                "required": ["id", "start"],
                "additionalProperties": False,
            },
        },
    },
    "required": ["scenario", "dispatcher", "tasks", "robots"],
    "additionalProperties": False,
}

# A file that `extends:` another needs only what it changes.
EXTENDING_SCHEMA: dict[str, Any] = {
    **SCENARIO_SCHEMA,
    "properties": {**SCENARIO_SCHEMA["properties"], "extends": {"type": "string", "description": "Scenario file this one starts from."}},
    "required": ["extends", "scenario"],
}


@dataclass
class TaskParams:
    """One task's plant parameters (thesis Table 5) and its fleet specification keys."""

    id: str
    source: tuple[float, float]
    destination: tuple[float, float]
    iFr: float = 30.0
    iBC: int = 100
    qSC: int = 100
    iBM: int = 0
    sPPi: float = 0.5
    sCDr: float = 0.0
    demand: tuple[float, float] = (0.0, 0.0)
    spec: dict[str, Any] = field(default_factory=dict)


@dataclass
class RobotParams:
    """One robot's plant parameters and its fleet specification keys."""

    id: str
    start: tuple[float, float, float]
    loadcap: int = 20
    spec: dict[str, Any] = field(default_factory=dict)


@dataclass
class Scenario:
    """A checked scenario file."""

    path: Path
    name: str
    title: str
    thesis: str
    dispatcher: str
    tasks: list[TaskParams]
    robots: list[RobotParams]
    stop: str = "any_full"
    time_limit: float = 3600.0
    record_every: float = 1.0
    seed: int = 1
    model: Path | None = None
    decision_interval: float = 1.0
    handling_time: float = 0.0
    park_after: float = 0.0
    skip_full: bool = False
    raw: dict[str, Any] = field(default_factory=dict)
    source: SourceMap | None = None

    @property
    def single_robot(self) -> bool:
        return len(self.robots) == 1

    def with_dispatcher(self, dispatcher: str, model: Path | None = None) -> Scenario:
        """The same plant under another dispatcher (for comparisons); `model` for the SVM."""
        if dispatcher == self.dispatcher and model in (None, self.model):
            return self
        return replace(self, dispatcher=dispatcher, name=f"{self.name}-{dispatcher}", model=model or self.model)


def load_scenario(path: str | Path, _chain: tuple[Path, ...] = ()) -> Scenario:
    """Load and check a scenario file; raise ConfigError listing every problem.

    A file with `extends: OTHER.yaml` starts from that scenario: its `scenario:` keys are
    merged, and any `dispatcher:`, `tasks:` or `robots:` section it gives replaces the other's.
    """
    path = Path(path)
    data, source = load_yaml(path)
    if not isinstance(data, dict):
        raise ConfigError([source.problem((), "a scenario file must be a mapping with scenario, dispatcher, tasks and robots")])
    extends = data.get("extends")
    problems = schema_problems(data, source, EXTENDING_SCHEMA if extends is not None else SCENARIO_SCHEMA)
    if problems:
        raise ConfigError(problems)
    base: Scenario | None = None
    if extends is not None:
        base_path = (path.parent / extends).resolve()
        if base_path in _chain or base_path == path.resolve():
            raise ConfigError([source.problem(("extends",), f"'{extends}' extends itself (directly or through others)")])
        if not base_path.exists():
            raise ConfigError([source.problem(("extends",), f"no scenario file {base_path}")])
        base = load_scenario(base_path, (*_chain, path.resolve()))
    for kind in ("tasks", "robots"):
        seen: set[str] = set()
        for index, item in enumerate(data.get(kind) or []):
            if item["id"] in seen:
                problems.append(source.problem((kind, index, "id"), f"duplicate id '{item['id']}'"))
            seen.add(item["id"])
    head = {**(base.raw.get("scenario", {}) if base else {}), **data.get("scenario", {})}
    plant = {**(base.raw.get("plant", {}) if base else {}), **data.get("plant", {})}
    dispatcher = data.get("dispatcher")
    if dispatcher is not None:
        kind, model, interval = dispatcher["type"], None, float(dispatcher.get("interval", 1.0))
        skip_full = bool(dispatcher.get("skip_full", False))
        if kind == "svm":
            if "model" not in dispatcher:
                problems.append(source.problem(("dispatcher",), "the svm dispatcher needs 'model: FILE.json' (softplc svm train)", at_key=True))
            else:
                model = (path.parent / dispatcher["model"]).resolve()
                if not model.exists():
                    problems.append(source.problem(("dispatcher", "model"), f"no model file {model}"))
    else:
        assert base is not None  # the schema requires a dispatcher unless the file extends another
        kind, model, interval, skip_full = base.dispatcher, base.model, base.decision_interval, base.skip_full
    if problems:
        raise ConfigError(problems)
    tasks = [_task(item) for item in data["tasks"]] if "tasks" in data else list(base.tasks) if base else []
    robots = [_robot(item) for item in data["robots"]] if "robots" in data else list(base.robots) if base else []
    return Scenario(
        path=path,
        name=head["name"],
        title=head.get("title", head["name"]),
        thesis=head.get("thesis", ""),
        dispatcher=kind,
        tasks=tasks,
        robots=robots,
        stop=head.get("stop", "any_full"),
        time_limit=float(head.get("time_limit", 3600.0)),
        record_every=float(head.get("record_every", 1.0)),
        seed=int(head.get("seed", 1)),
        model=model,
        decision_interval=interval,
        handling_time=float(plant.get("handling_time", 0.0)),
        park_after=float(plant.get("park_after", 0.0)),
        skip_full=skip_full,
        raw={**data, "scenario": head, "plant": plant},
        source=source,
    )


def _task(item: dict[str, Any]) -> TaskParams:
    demand = item.get("demand", [0, 0])
    return TaskParams(
        id=item["id"],
        source=(float(item["source"]["x"]), float(item["source"]["y"])),
        destination=(float(item["destination"]["x"]), float(item["destination"]["y"])),
        iFr=float(item.get("iFr", 30.0)),
        iBC=int(item.get("iBC", 100)),
        qSC=int(item.get("qSC", 100)),
        iBM=int(item.get("iBM", 0)),
        sPPi=float(item.get("sPPi", 0.5)),
        sCDr=float(item.get("sCDr", 0.0)),
        demand=(float(demand[0]), float(demand[1])),
        spec={key: item[key] for key in TASK_SPEC_KEYS if key in item},
    )


def _robot(item: dict[str, Any]) -> RobotParams:
    start = item["start"]
    return RobotParams(
        id=item["id"],
        start=(float(start["x"]), float(start["y"]), float(start.get("heading", 0.0))),
        loadcap=int(item.get("loadcap", 20)),
        spec={key: item[key] for key in ROBOT_SPEC_KEYS if key in item},
    )


def builtin_scenarios() -> list[Path]:
    """The scenario files shipped in the project's `scenarios/` folder, by name."""
    return sorted(BUILTIN_DIR.glob("*.yaml"))


def find_scenario(name_or_file: str) -> Path:
    """A scenario file by path, or by the name of a shipped scenario; FileNotFoundError says what exists."""
    candidate = Path(name_or_file)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists():
        if not candidate.exists():
            raise FileNotFoundError(f"no scenario file {candidate}")
        return candidate
    names = {path.stem: path for path in builtin_scenarios()}
    if name_or_file in names:
        return names[name_or_file]
    known = ", ".join(names) or "none"
    raise FileNotFoundError(f"no scenario '{name_or_file}'{did_you_mean(name_or_file, names)}; shipped: {known}")
