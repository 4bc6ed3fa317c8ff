"""A trip: one goal of one vehicle as a VDA 5050 order on the roadmap, its updates and their acknowledgement.

The route (node ids, from the node the vehicle stands on to the goal's node) is fixed when the
trip starts; node i gets sequenceId 2i, the edge after it 2i+1, for the whole order (§6.6.2).
`released` is the index of the decision point: nodes 0…released and the edges between them
are the base, the rest the horizon. Each release (traffic.py) is an order update stitched at
the previous decision point: same orderId, orderUpdateId + 1, starting with that node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from softplc.protocols.vda5050.messages import edge, node
from softplc.robotics.roadmap import Roadmap


@dataclass
class Trip:
    """One order to one vehicle (see the module docstring)."""

    order_id: str
    route: list[str]
    goal: tuple[float, float]
    goal_actions: list[dict[str, Any]] = field(default_factory=list)  # run on the last node (pick, drop)
    first_deviation: float = 0.3  # the first node's allowedDeviationXY: wide enough to hold where the vehicle stands
    released: int = 0  # index of the decision point
    passed: int = 0  # index of the node the vehicle last traversed (as its state says)
    update_id: int = -1  # orderUpdateId of the last message sent (-1: nothing sent yet)
    sent_from: int = 0  # the node index the last message started at (its stitching node)
    body: dict[str, Any] | None = None  # the last order sent, without header: what a resend repeats
    sent_at: float = -math.inf
    acknowledged_update: int = -1  # highest orderUpdateId a state confirmed
    resends: int = 0
    make_way: bool = False  # not the plant's goal: moving an idle vehicle out of another's way
    old_errors: set[str] = field(default_factory=set)
    rerouted: tuple[float, int] = (-math.inf, -1)  # when a deadlock re-routed it last, and where it was then  # errors the vehicle reported before: not a rejection of this trip
    done: bool = False
    failed: str = ""

    @property
    def goal_node(self) -> str:
        return self.route[-1]

    @property
    def acknowledged(self) -> bool:
        return self.update_id >= 0 and self.acknowledged_update >= self.update_id

    def position(self, last_node_id: str, last_sequence_id: int) -> int:
        """Index on the route of the node the vehicle last traversed (-1: not on this order yet)."""
        index = last_sequence_id // 2
        if last_sequence_id % 2 == 0 and 0 <= index < len(self.route) and self.route[index] == last_node_id:
            return index
        return -1

    def message(self, roadmap: Roadmap) -> dict[str, Any]:
        """The next order message: the first one, or an update stitched at the previous decision point."""
        start = 0 if self.update_id < 0 else self.sent_from
        nodes = []
        for index in range(start, len(self.route)):
            road_node = roadmap.nodes[self.route[index]]
            deviation = self.first_deviation if index == 0 else roadmap.deviation
            actions = self.goal_actions if index == len(self.route) - 1 else []
            nodes.append(node(road_node.id, 2 * index, index <= self.released, road_node.x, road_node.y, roadmap.map_id,
                              deviation=deviation, actions=[dict(action) for action in actions]))
        edges = []
        for index in range(start, len(self.route) - 1):
            lane = roadmap.lane(self.route[index], self.route[index + 1])
            assert lane is not None, "a route follows the lanes"
            edges.append(edge(lane.id, 2 * index + 1, index + 1 <= self.released, lane.start, lane.end,
                              max_speed=lane.max_speed, length=round(lane.length, 3)))
        return {"orderId": self.order_id, "orderUpdateId": self.update_id + 1, "nodes": nodes, "edges": edges}

    def sent(self, body: dict[str, Any], now: float) -> None:
        self.body = body
        self.update_id = body["orderUpdateId"]
        self.sent_from = self.released
        self.sent_at = now

    @property
    def base(self) -> list[str]:
        """The released nodes still ahead, from the one the vehicle last traversed."""
        return self.route[self.passed: self.released + 1]

    @property
    def horizon(self) -> list[str]:
        return self.route[self.released + 1:]


def load_actions(kind: str, action_id: str, parameters: dict[str, Any]) -> list[dict[str, Any]]:
    """A pick or drop at the goal (HARD: the vehicle stands while its load handling works), or none."""
    if kind not in ("pick", "drop"):
        return []
    action: dict[str, Any] = {"actionType": kind, "actionId": action_id, "blockingType": "HARD"}
    if parameters:
        action["actionParameters"] = [{"key": key, "value": value} for key, value in parameters.items()]
    return [action]
