"""What a robot knows of the other robots: their tags, and nothing else (thesis §3.7).

A `PeerView` is built from the robots' tag values (`rNN_xpos`, `rNN_ypos`, `rNN_heading`,
`rNN_speed`, `rNN_navstate`, `rNN_radius`, `rNN_route`) — in-process from the tag database, in a
remote agent from its OPC UA subscriptions — so robots never talk to each other directly.
Priority between robots is deterministic: the robot whose id sorts first has right of way.
A robot's route (`rNN_route`, "x,y x,y ...") is the path it is following, so robots without
right of way can get out of its way.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SMALL_FLEET = 16  # robots below which `near` computes with Python floats, not arrays
GRID_FROM = 64  # robots from which `near` looks in grid cells instead of at every robot
GRID_CELL = 3.0  # metres, a cell's side: a robot's sense range (traffic.py) spans 2-3 cells

ACTIVE_STATES = frozenset({"planning", "moving", "blocked"})
PEER_TAGS = ("xpos", "ypos", "heading", "speed", "navstate", "radius", "route", "navreason")


@dataclass
class Peer:
    """Another robot as seen through its tags."""

    id: str
    x: float
    y: float
    heading: float
    speed: float
    active: bool  # navigating: it may move on its own; otherwise a static obstacle
    radius: float
    rank: int  # 0 has right of way over everyone
    route: list[tuple[float, float]] = field(default_factory=list)
    reason: str = ""  # its navreason, e.g. "waiting for r07"

    def remaining_route(self, fallback_length: float = 1.5) -> list[tuple[float, float]]:
        """Where it is going: its route from the point nearest to it on (or straight ahead)."""
        route = self.route
        if len(route) < 2:
            return [(self.x, self.y), (self.x + fallback_length * math.cos(self.heading), self.y + fallback_length * math.sin(self.heading))]
        best, best_index = math.inf, 0
        for index, (a, b) in enumerate(zip(route, route[1:])):
            distance = _segment_distance(self.x, self.y, a, b)
            if distance < best:
                best, best_index = distance, index
        return [(self.x, self.y), *route[best_index + 1 :]]


class PeerView:
    """Every robot's published state at one instant, with fast nearest-robot queries."""

    def __init__(self, ids: Sequence[str], values: Sequence[Sequence[Any]]) -> None:
        self.ids = list(ids)
        self.index = {robot_id: position for position, robot_id in enumerate(self.ids)}
        rows = list(values)
        self.x = np.array([_number(row[0]) for row in rows], dtype=float)
        self.y = np.array([_number(row[1]) for row in rows], dtype=float)
        self.heading = [_number(row[2]) for row in rows]
        self.speed = [_number(row[3]) for row in rows]
        self.active = [row[4] in ACTIVE_STATES for row in rows]
        self.radius = [_number(row[5]) or 0.2 for row in rows]
        self.routes = [row[6] if len(row) > 6 and isinstance(row[6], str) else "" for row in rows]
        self.reasons = [row[7] if len(row) > 7 and isinstance(row[7], str) else "" for row in rows]
        ranking = sorted(self.ids)
        self.rank = {robot_id: position for position, robot_id in enumerate(ranking)}
        # Every robot asks for its neighbours every cycle, and each is the neighbour of a few:
        # a Peer is made once per change of its robot's tags, and a large fleet's positions
        # are sorted into grid cells once per change of any position (see `near`).
        self._peers: list[Peer | None] = [None] * len(self.ids)
        self._cells: dict[tuple[int, int], list[int]] | None = None

    @classmethod
    def from_tags(cls, ids: Sequence[str], value: Callable[[str], Any]) -> PeerView:
        """Read the peer tags of `ids` through `value(tag_name)`."""
        return cls(ids, [[value(f"{robot_id}_{tag}") for tag in PEER_TAGS] for robot_id in ids])

    def __len__(self) -> int:
        return len(self.ids)

    def update(self, position: int, tag: str, value: Any) -> None:
        """Take one changed tag value (`tag` is one of PEER_TAGS) of the robot at `position`."""
        self._peers[position] = None
        if tag == "xpos":
            self.x[position] = _number(value)
            self._cells = None
        elif tag == "ypos":
            self.y[position] = _number(value)
            self._cells = None
        elif tag == "heading":
            self.heading[position] = _number(value)
        elif tag == "speed":
            self.speed[position] = _number(value)
        elif tag == "navstate":
            self.active[position] = value in ACTIVE_STATES
        elif tag == "radius":
            self.radius[position] = _number(value) or 0.2
        elif tag == "route":
            self.routes[position] = value if isinstance(value, str) else ""
        elif tag == "navreason":
            self.reasons[position] = value if isinstance(value, str) else ""

    def peer(self, position: int) -> Peer:
        """The robot at `position` as a Peer (the same object until one of its tags changes: do not modify it)."""
        known = self._peers[position]
        if known is not None:
            return known
        robot_id = self.ids[position]
        known = self._peers[position] = Peer(
            robot_id,
            float(self.x[position]),
            float(self.y[position]),
            self.heading[position],
            self.speed[position],
            self.active[position],
            self.radius[position],
            self.rank[robot_id],
            decode_route(self.routes[position]) if self.active[position] else [],
            self.reasons[position],
        )
        return known

    def near(self, robot_id: str, x: float, y: float, within: float) -> list[Peer]:
        """Other robots whose centre is within `within` metres of (x, y), nearest first (ties: by position)."""
        if not self.ids:
            return []
        me = self.index.get(robot_id)
        if len(self.ids) < SMALL_FLEET:
            # A few robots: plain floats beat the arrays' per-call cost (~8 µs of a ~40 µs step).
            distances = [math.hypot(px - x, py - y) for px, py in zip(self.x.tolist(), self.y.tolist())]
            near = [(distance, c) for c, distance in enumerate(distances) if distance <= within and c != me]
            near.sort()
            return [self.peer(c) for _, c in near]
        if len(self.ids) < GRID_FROM:
            distance = np.hypot(self.x - x, self.y - y)
            result = [int(c) for c in np.nonzero(distance <= within)[0] if c != me]
            result.sort(key=lambda c: distance[c])
            return [self.peer(c) for c in result]
        # Only the robots of the grid cells within reach: the distance to each of a thousand
        # robots, for each of them, every cycle, cost 13.5 µs of a ~60 µs step (1,000 robots), the grid 8.7 µs.
        candidates = self._within_cells(x, y, within)
        distance = np.hypot(self.x[candidates] - x, self.y[candidates] - y)
        found = [(float(distance[i]), int(c)) for i, c in enumerate(candidates.tolist()) if distance[i] <= within and c != me]
        found.sort()
        return [self.peer(c) for _, c in found]

    def _within_cells(self, x: float, y: float, within: float) -> np.ndarray:
        """Positions, ascending, of the robots in the grid cells that can hold a centre within `within` of (x, y)."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(within)):
            return np.arange(len(self.ids))  # no cell to look in: every robot, as without the grid
        cells = self._cells
        if cells is None:
            cells = self._cells = {}
            for position, (px, py) in enumerate(zip(self.x.tolist(), self.y.tolist())):
                if math.isfinite(px) and math.isfinite(py):  # NaN and inf are near nothing
                    cells.setdefault((math.floor(px / GRID_CELL), math.floor(py / GRID_CELL)), []).append(position)
        found: list[int] = []
        columns = range(math.floor((x - within) / GRID_CELL), math.floor((x + within) / GRID_CELL) + 1)
        rows = range(math.floor((y - within) / GRID_CELL), math.floor((y + within) / GRID_CELL) + 1)
        if len(columns) * len(rows) > len(self.ids):  # a reach over much of the floor: every robot is quicker
            return np.arange(len(self.ids))
        for i in columns:
            for j in rows:
                found.extend(cells.get((i, j), ()))
        found.sort()
        return np.array(found, dtype=np.intp)

    def rank_of(self, robot_id: str) -> int:
        return self.rank.get(robot_id, len(self.rank))


def encode_route(path: Sequence[tuple[float, float]]) -> str:
    """'x,y x,y ...' in centimetres, for the rNN_route tag."""
    return " ".join(f"{x:.2f},{y:.2f}" for x, y in path)


@functools.lru_cache(maxsize=4096)
def decode_route(text: str) -> list[tuple[float, float]]:
    """The points of a route tag ('' or garbage: no route)."""
    points = []
    for pair in text.split():
        x, _, y = pair.partition(",")
        try:
            points.append((float(x), float(y)))
        except ValueError:
            return []
    return points


def _segment_distance(px: float, py: float, a: tuple[float, float], b: tuple[float, float]) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = max(0.0, min(1.0, ((px - a[0]) * dx + (py - a[1]) * dy) / length2)) if length2 > 0 else 0.0
    return math.hypot(px - (a[0] + t * dx), py - (a[1] + t * dy))


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return 0.0
