"""The plant configuration of a scenario: tags, scan tasks and programs, as tagdb.yaml text.

The same structure as the default `tagdb.yaml` (robot and task templates with the thesis's
Table 5 tags), plus the tags the case-study programs add: `rNN_tnext` (the dispatcher's
choice), `tNN_Tw` (task weight, or assignment cost), `tNN_goals` (goals issued) and
`svm_out`. The text is written next to a run's records (`plant.yaml`) so it can be read.
"""

from __future__ import annotations

import sys
from typing import Any

import yaml

from softplc.config import PlantConfig, parse_config
from softplc.config.yamlsource import ConfigError, Location, Problem, load_yaml
from softplc.scenarios.spec import PROJECT, Scenario

ROBOT_TAGS: dict[str, dict[str, Any]] = {
    "xpos": {"type": "float64", "unit": "m", "access": "ro", "description": "x position"},
    "ypos": {"type": "float64", "unit": "m", "access": "ro", "description": "y position"},
    "status": {"type": "bool", "description": "busy; the robot clears it at its goal"},
    "tcurr": {"type": "uint16", "description": "current task number"},
    "currloc": {"type": "uint16", "min": 0, "max": 4, "description": "motion state 0..4"},
    "prevloc": {"type": "uint16", "min": 0, "max": 4, "description": "previous motion state"},
    "xgoal": {"type": "float64", "unit": "m", "description": "x goal"},
    "ygoal": {"type": "float64", "unit": "m", "description": "y goal"},
    "loadcap": {"type": "uint16", "unit": "items", "description": "load capacity"},
    "load": {"type": "uint16", "unit": "items", "description": "current load"},
    # the plant sets it when loading is done, the sequencer clears it: a handshake, shared on purpose
    "loadstat": {"type": "bool", "description": "loading/unloading done", "shared_output": True},
    "tnext": {"type": "uint16", "description": "task chosen by the dispatcher for the next trip (0 = none)"},
}

# Tags the fleet's robot driver publishes; declared as in the default plant (tagdb.yaml),
# which the fleet keeps in step with its adapter — these are only the fallback.
FLEET_TAGS: dict[str, dict[str, Any]] = {
    "heading": {"type": "float64", "unit": "rad", "access": "ro", "description": "heading"},
    "speed": {"type": "float64", "unit": "m/s", "access": "ro", "description": "linear speed"},
    "navstate": {"type": "string", "initial": "idle", "access": "ro", "description": "navigation state"},
    "navreason": {"type": "string", "access": "ro", "description": "why blocked or failed"},
    "radius": {"type": "float64", "unit": "m", "access": "ro", "description": "footprint radius"},
    "route": {"type": "string", "access": "ro", "description": "path being followed, 'x,y x,y ...'"},
}

TASK_TAGS: dict[str, dict[str, Any]] = {
    "iBM": {"type": "uint16", "unit": "items", "description": "input buffer items"},
    "iBL": {"type": "float32", "unit": "%", "access": "ro", "description": "input buffer level"},
    "iFr": {"type": "float32", "unit": "items/min", "description": "input fill rate"},
    "iBC": {"type": "uint16", "unit": "items", "min": 1, "initial": 100, "description": "input buffer capacity"},
    "qSM": {"type": "uint16", "unit": "items", "description": "output storage items"},
    "qSL": {"type": "float32", "unit": "%", "access": "ro", "description": "output storage level"},
    "qFr": {"type": "float32", "unit": "%/min", "access": "ro", "description": "output fill rate"},
    "qSC": {"type": "uint16", "unit": "items", "min": 1, "initial": 100, "description": "output storage capacity"},
    "sCDr": {"type": "float32", "description": "supply chain consumer demand rate"},
    "sPPi": {"type": "float32", "initial": 0.5, "description": "profit per product index"},
    "sPD": {"type": "float32", "unit": "%", "description": "current product demand"},
    "src_x": {"type": "float64", "unit": "m", "description": "source x"},
    "src_y": {"type": "float64", "unit": "m", "description": "source y"},
    "dest_x": {"type": "float64", "unit": "m", "description": "destination x"},
    "dest_y": {"type": "float64", "unit": "m", "description": "destination y"},
    "Tw": {"type": "float64", "access": "ro", "description": "task weight (or assignment cost) from the dispatcher"},
    # every robot's sequencer adds its goals (an InOut in one task): shared on purpose
    "goals": {"type": "uint32", "access": "ro", "description": "goals issued for this task", "shared_output": True},
}

PLANT_INTERVAL = "100ms"


def robot_tags() -> dict[str, dict[str, Any]]:
    """The case-study robot tags plus every tag the fleet adapter needs."""
    from softplc.adapters.fleet.adapter import REQUIRED_TAGS

    try:
        default_plant, _ = load_yaml(PROJECT / "tagdb.yaml")
        declared = default_plant["templates"]["robot"]["tags"]
    except (ConfigError, KeyError, TypeError):
        declared = {}
    tags = dict(ROBOT_TAGS)
    for name in REQUIRED_TAGS:
        if name not in tags:
            definition = declared.get(name) or FLEET_TAGS.get(name)
            if definition is None:
                raise ConfigError([Problem(Location(str(PROJECT / "tagdb.yaml"), 1, 1),
                                           f"the fleet needs robot tag '{name}', which the robot template does not declare")])
            tags[name] = definition
    return tags


def _each(prefixes: list[str], tag: str) -> list[str]:
    return [f"{prefix}_{tag}" for prefix in prefixes]


def plant_document(scenario: Scenario, compatible: list[list[int]]) -> dict[str, Any]:
    """The plant configuration as a tagdb.yaml document (a dict)."""
    tasks = [task.id for task in scenario.tasks]
    robots = [robot.id for robot in scenario.robots]
    task_initial = {
        task.id: {
            "iFr": task.iFr, "iBC": task.iBC, "qSC": task.qSC, "iBM": task.iBM, "sPPi": task.sPPi, "sCDr": task.sCDr,
            "sPD": task.demand[0], "src_x": task.source[0], "src_y": task.source[1],
            "dest_x": task.destination[0], "dest_y": task.destination[1],
        }
        for task in scenario.tasks
    }
    robot_initial = {
        robot.id: {"xpos": robot.start[0], "ypos": robot.start[1], "heading": robot.start[2], "xgoal": robot.start[0],
                   "ygoal": robot.start[1], "loadcap": robot.loadcap}
        for robot in scenario.robots
    }
    plant_programs: list[dict[str, Any]] = [{
        "name": "plant",
        "program": "programs.plant_simulator:MaterialHandlingPlant",
        "bind": {
            **{tag: _each(tasks, tag) for tag in ("iBM", "iBC", "iFr", "iBL", "qSM", "qSC", "qSL", "qFr")},
            **{tag: _each(robots, tag) for tag in ("tcurr", "currloc", "loadcap", "load", "loadstat")},
        },
        "params": {"handling_time": scenario.handling_time},
    }]
    if any(task.demand[0] != task.demand[1] for task in scenario.tasks):
        plant_programs.append({
            "name": "demand",
            "program": "programs.supply_chain:DemandGenerator",
            "bind": {"sPD": _each(tasks, "sPD")},
            "params": {"low": [task.demand[0] for task in scenario.tasks], "high": [task.demand[1] for task in scenario.tasks],
                       "seed": scenario.seed},
        })
    sequencer = {
        "name": "motion_{robot}",
        "program": "programs.motion_sequencer:MotionSequencer",
        "for_each": "robot",
        "bind": {
            **{tag: "{robot}_" + tag for tag in ("xpos", "ypos", "xgoal", "ygoal", "status", "currloc", "prevloc", "tcurr",
                                                  "loadstat", "tnext")},
            **{tag: _each(tasks, tag) for tag in ("src_x", "src_y", "dest_x", "dest_y", "goals")},
        },
        "params": {"park_after": scenario.park_after},
    }
    document: dict[str, Any] = {
        "version": 1,
        "plant": {"name": scenario.name, "description": scenario.title},
        "templates": {
            "robot": {"group": "Robots", "instances": robots, "tags": robot_tags(), "initial": robot_initial},
            "task": {"group": "Tasks", "instances": tasks, "tags": TASK_TAGS, "initial": task_initial},
        },
        "tags": {"svm_out": {"type": "uint16", "access": "ro", "description": "task chosen by the SVM (1, 2, ...)"}},
        "tasks": {
            # the plant first, then the robots' sequencers: the thesis's loop (matHand_sim, then robMotion)
            "plant": {"interval": PLANT_INTERVAL, "priority": 5, "programs": [*plant_programs, sequencer]},
            "dispatch": {"interval": scenario.decision_interval, "priority": 7, "programs": [dispatcher_program(scenario, compatible)]},
        },
    }
    return document


def dispatcher_program(scenario: Scenario, compatible: list[list[int]]) -> dict[str, Any]:
    """The dispatcher's program entry for the scenario's dispatcher type."""
    from softplc.scenarios.fleet import team_sizes

    tasks = [task.id for task in scenario.tasks]
    robots = [robot.id for robot in scenario.robots]
    kind = scenario.dispatcher
    # Every dispatcher keeps each task's team within its max_team_size (0: no limit), counting
    # the robots on a task from their tcurr and currloc (programs/teams.py).
    teams = {tag: _each(robots, tag) for tag in ("tnext", "tcurr", "currloc")}
    limits = {"max_team": team_sizes(scenario)} if any(size > 0 for size in team_sizes(scenario)) else {}
    if kind in ("weighting", "cooperative"):
        entry: dict[str, Any] = {
            "name": "dispatch",
            "program": "programs.task_weighting:TaskWeighting" if kind == "weighting" else
                       "programs.cooperative_dispatcher:CooperativeDispatcher",
            "bind": {**{tag: _each(tasks, tag) for tag in ("iFr", "iBL", "iBC", "sPPi", "qFr", "qSL", "sCDr", "sPD", "Tw")}, **teams},
        }
        entry["params"] = {"skip_full": scenario.skip_full, **limits}
        if kind == "cooperative":
            entry["params"]["compatible"] = compatible
        return entry
    if kind == "svm":
        return {
            "name": "dispatch",
            "program": "programs.svm_dispatcher:SvmDispatcher",
            "bind": {**{tag: _each(tasks, tag) for tag in ("iBL", "qSL", "sPD")}, **teams, "svm_out": "svm_out"},
            "params": {"model": str(scenario.model), "skip_full": scenario.skip_full, **limits},
        }
    return {
        "name": "dispatch",
        "program": "programs.optimal_dispatcher:OptimalAssignment",
        "bind": {
            **{tag: _each(tasks, tag) for tag in ("iBM", "iFr", "qSM", "qSC", "src_x", "src_y", "dest_x", "dest_y")},
            "cost": _each(tasks, "Tw"),
            **{tag: _each(robots, tag) for tag in ("xpos", "ypos", "loadcap", "load", "currloc", "tcurr", "tnext")},
        },
        "params": {"compatible": compatible, **limits},
    }


def plant_yaml(scenario: Scenario, compatible: list[list[int]]) -> str:
    header = f"# Plant of scenario '{scenario.name}' ({scenario.path.name}), generated by softplc scenario run.\n"
    return header + yaml.safe_dump(plant_document(scenario, compatible), sort_keys=False, width=120)


def build_plant(scenario: Scenario, compatible: list[list[int]]) -> tuple[PlantConfig, str]:
    """The checked PlantConfig of a scenario, and its YAML text."""
    if str(PROJECT) not in sys.path:
        sys.path.insert(0, str(PROJECT))  # the shipped `programs` package lives next to `softplc`
    text = plant_yaml(scenario, compatible)
    return parse_config(text, PROJECT / f"{scenario.name}.plant.yaml"), text
