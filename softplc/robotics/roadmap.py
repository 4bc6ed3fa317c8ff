"""The plant's roadmap: the navigation graph VDA 5050 orders are made of (stations, waypoints, lanes).

    roadmap:
      map_id: factory               # the VDA 5050 mapId of every node (default: the file's name)
      deviation: 0.3                # m, allowedDeviationXY of every node (default 0.3)
      load_handling: {stationType: floor, loadType: EPAL}   # parameters of the pick and drop actions
      stations:                     # where robots load and unload: a goal there gets pick/drop actions
        - {id: t01_src, x: 3.5, y: 7.5}
      waypoints:                    # the crossings and bends of the lanes
        - {id: w01, x: 3.5, y: 6.2}
      lanes:                        # both ways unless one_way: true; max_speed in m/s (optional)
        - {from: t01_src, to: w01}
        - {from: w01, to: w02, one_way: true, max_speed: 0.5}

Each lane is one edge per direction, named `FROM-TO`. `Roadmap.route(a, b)` is the shortest
path (Dijkstra on lane lengths), `nearest(x, y)` the node a pose or a goal maps to. Every
mistake is reported as `FILE:LINE:COL: message`, like robots.yaml.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from softplc.config import did_you_mean, schema_problems
from softplc.config.yamlsource import ConfigError, Problem, SourceMap, load_yaml, parse_yaml

ID_PATTERN = r"^[A-Za-z0-9_.:]+$"  # the spec's id characters without '-', which joins edge ids

_NODE = {
    "type": "object",
    "properties": {"id": {"type": "string", "pattern": ID_PATTERN}, "x": {"type": "number"}, "y": {"type": "number"},
                   "name": {"type": "string"}},
    "required": ["id", "x", "y"],
    "additionalProperties": False,
}
_LANE = {
    "type": "object",
    "properties": {"from": {"type": "string"}, "to": {"type": "string"}, "one_way": {"type": "boolean"},
                   "max_speed": {"type": "number", "exclusiveMinimum": 0}},
    "required": ["from", "to"],
    "additionalProperties": False,
}
SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "roadmap": {
            "type": "object",
            "properties": {
                "map_id": {"type": "string", "pattern": ID_PATTERN},
                "deviation": {"type": "number", "exclusiveMinimum": 0},
                "load_handling": {"type": "object"},
                "stations": {"type": "array", "items": _NODE},
                "waypoints": {"type": "array", "items": _NODE},
                "lanes": {"type": "array", "items": _LANE, "minItems": 1},
            },
            "required": ["lanes"],
            "additionalProperties": False,
        }
    },
    "required": ["roadmap"],
    "additionalProperties": False,
}


@dataclass(frozen=True)
class RoadNode:
    id: str
    x: float
    y: float
    station: bool
    name: str = ""


@dataclass(frozen=True)
class Lane:
    """One direction of a lane: a VDA 5050 edge."""

    id: str
    start: str
    end: str
    length: float
    max_speed: float | None = None


@dataclass
class Roadmap:
    """A checked roadmap (see the module docstring)."""

    path: Path
    map_id: str
    deviation: float
    nodes: dict[str, RoadNode]
    lanes: dict[str, Lane]  # by edge id
    load_handling: dict[str, Any] = field(default_factory=dict)
    _out: dict[str, list[Lane]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        for lane in self.lanes.values():
            self._out.setdefault(lane.start, []).append(lane)

    def lane(self, start: str, end: str) -> Lane | None:
        for lane in self._out.get(start, ()):
            if lane.end == end:
                return lane
        return None

    def nearest(self, x: float, y: float, *, stations_only: bool = False) -> RoadNode:
        """The node closest to (x, y) (ties: the first declared)."""
        candidates = [node for node in self.nodes.values() if node.station or not stations_only] or list(self.nodes.values())
        return min(candidates, key=lambda node: math.hypot(node.x - x, node.y - y))

    def route(self, start: str, goal: str, *, avoid: frozenset[str] = frozenset()) -> list[str] | None:
        """The shortest node sequence from start to goal along the lanes (None when unreachable); `avoid`: nodes not to pass."""
        if start == goal:
            return [start]
        distances = {start: 0.0}
        previous: dict[str, str] = {}
        queue = [(0.0, start)]
        while queue:
            distance, here = heapq.heappop(queue)
            if here == goal:
                break
            if distance > distances.get(here, math.inf):
                continue
            for lane in self._out.get(here, ()):
                if lane.end in avoid and lane.end != goal:
                    continue
                candidate = distance + lane.length
                if candidate < distances.get(lane.end, math.inf):
                    distances[lane.end] = candidate
                    previous[lane.end] = here
                    heapq.heappush(queue, (candidate, lane.end))
        if goal not in previous:
            return None
        path = [goal]
        while path[-1] != start:
            path.append(previous[path[-1]])
        return path[::-1]


def load_roadmap(path: str | Path) -> Roadmap:
    """Load and check a roadmap file; ConfigError lists every problem, located."""
    data, source = load_yaml(path)
    return _roadmap_from(Path(path), data, source)


def parse_roadmap(text: str, path: str | Path = "<roadmap>") -> Roadmap:
    data, source = parse_yaml(text, str(path))
    return _roadmap_from(Path(path), data, source)


def _roadmap_from(path: Path, data: Any, source: SourceMap) -> Roadmap:
    if not isinstance(data, dict):
        raise ConfigError([source.problem((), "the file must be a mapping with a 'roadmap:' section")])
    problems = schema_problems(data, source, SCHEMA)
    if problems:
        raise ConfigError(problems)
    section = data["roadmap"]
    nodes: dict[str, RoadNode] = {}
    found: list[Problem] = []
    for kind in ("stations", "waypoints"):
        for index, item in enumerate(section.get(kind, [])):
            if item["id"] in nodes:
                found.append(source.problem(("roadmap", kind, index, "id"), f"duplicate node id '{item['id']}'"))
                continue
            nodes[item["id"]] = RoadNode(item["id"], float(item["x"]), float(item["y"]), kind == "stations", item.get("name", ""))
    if not nodes:
        found.append(source.problem(("roadmap",), "a roadmap needs stations or waypoints (its nodes)"))
    lanes: dict[str, Lane] = {}
    for index, item in enumerate(section["lanes"]):
        ends = []
        for key in ("from", "to"):
            if item[key] not in nodes:
                found.append(source.problem(("roadmap", "lanes", index, key),
                                            f"no node '{item[key]}'{did_you_mean(item[key], list(nodes))}"))
            ends.append(item[key])
        if len(ends) != 2 or ends[0] not in nodes or ends[1] not in nodes:
            continue
        if ends[0] == ends[1]:
            found.append(source.problem(("roadmap", "lanes", index), f"lane from '{ends[0]}' to itself"))
            continue
        start, end = nodes[ends[0]], nodes[ends[1]]
        length = math.hypot(end.x - start.x, end.y - start.y)
        speed = float(item["max_speed"]) if "max_speed" in item else None
        directions = [(start.id, end.id)] if item.get("one_way") else [(start.id, end.id), (end.id, start.id)]
        taken = [f"{a} → {b}" for a, b in directions if f"{a}-{b}" in lanes]
        if taken:
            found.append(source.problem(("roadmap", "lanes", index), f"lane {taken[0]} declared twice"))
            continue
        for a, b in directions:
            lanes[f"{a}-{b}"] = Lane(f"{a}-{b}", a, b, length, speed)
    if found:
        raise ConfigError(found)
    load_handling = section.get("load_handling", {"stationType": "floor", "loadType": "EPAL"})
    return Roadmap(path, section.get("map_id", path.stem), float(section.get("deviation", 0.3)), nodes, lanes, dict(load_handling))
