"""What a robot knows of the other robots: their tags, and nothing else (thesis §3.7).

A `PeerView` is built from the robots' tag values (`rNN_xpos`, `rNN_ypos`, `rNN_heading`,
`rNN_speed`, `rNN_navstate`, `rNN_radius`) — in-process from the tag database, in a remote agent
from its OPC UA subscriptions — so robots never talk to each other directly. Priority between
robots is deterministic: the robot whose id sorts first has right of way.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

ACTIVE_STATES = frozenset({"planning", "moving", "blocked"})
PEER_TAGS = ("xpos", "ypos", "heading", "speed", "navstate", "radius")


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
        ranking = sorted(self.ids)
        self.rank = {robot_id: position for position, robot_id in enumerate(ranking)}

    @classmethod
    def from_tags(cls, ids: Sequence[str], value: Callable[[str], Any]) -> PeerView:
        """Read the peer tags of `ids` through `value(tag_name)`."""
        return cls(ids, [[value(f"{robot_id}_{tag}") for tag in PEER_TAGS] for robot_id in ids])

    def __len__(self) -> int:
        return len(self.ids)

    def peer(self, position: int) -> Peer:
        robot_id = self.ids[position]
        return Peer(
            robot_id,
            float(self.x[position]),
            float(self.y[position]),
            self.heading[position],
            self.speed[position],
            self.active[position],
            self.radius[position],
            self.rank[robot_id],
        )

    def near(self, robot_id: str, x: float, y: float, within: float) -> list[Peer]:
        """Other robots whose centre is within `within` metres of (x, y), nearest first."""
        if not self.ids:
            return []
        distance = np.hypot(self.x - x, self.y - y)
        candidates = np.nonzero(distance <= within)[0]
        me = self.index.get(robot_id)
        result = [int(c) for c in candidates if c != me]
        result.sort(key=lambda c: distance[c])
        return [self.peer(c) for c in result]

    def rank_of(self, robot_id: str) -> int:
        return self.rank.get(robot_id, len(self.rank))


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return 0.0
