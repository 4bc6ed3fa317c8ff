"""A VDA 5050 vehicle's order logic (spec 2.1 §6.6, §6.8–6.11): orders, updates, actions, state — no MQTT, no motion.

`Vehicle.on_order(payload)` and `on_instant_actions(payload)` take the master's messages;
`target(pose)` says where to drive next (the next released node, None to stand still: no order,
a decision point, paused, a blocking action running); `step(now, pose, moving)` traverses nodes
and runs their actions; `state()` is the state message's body. `changed` is set by every event
the spec names as a reason to send the state (§6.10). The agent (softplc.clients.robot_agent.vda5050.agent)
drives a simulated TurtleBot with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from softplc.protocols.vda5050.messages import instant_actions_of, parameters
from softplc.protocols.vda5050.validation import MessageError, decode
from softplc.robotics.robots import Pose

DEFAULT_DEVIATION = 0.25  # m: a node with allowedDeviationXY 0 or none counts as reached this close
ACTION_SECONDS = 2.0  # how long a pick or drop takes unless its `duration` parameter says otherwise
INSTANT = ("cancelOrder", "startPause", "stopPause", "initPosition", "factsheetRequest", "stateRequest")
NODE_ACTIONS = ("pick", "drop", "wait")


@dataclass
class ActionRun:
    """One action of the order or an instant action, as reported in actionStates."""

    id: str
    type: str
    blocking: str
    params: dict[str, Any]
    status: str = "WAITING"
    result: str = ""
    ends_at: float = math.inf
    instant: bool = False


@dataclass
class Waypoint:
    node_id: str
    sequence_id: int
    released: bool
    x: float | None
    y: float | None
    deviation: float
    actions: list[str] = field(default_factory=list)  # action ids


class Vehicle:
    """See the module docstring."""

    def __init__(self, version: str, *, load_capacity: int = 1) -> None:
        self.version = version
        self.order_id = ""
        self.order_update_id = 0
        self.last_node_id = ""
        self.last_node_sequence_id = 0
        self.nodes: list[Waypoint] = []  # still to be traversed (nodeStates)
        self.edges: list[tuple[str, int, bool]] = []  # edgeStates: edgeId, sequenceId, released
        self.actions: dict[str, ActionRun] = {}
        self.errors: list[dict[str, Any]] = []
        self.paused = False
        self.loads: list[dict[str, Any]] = []
        self.load_capacity = load_capacity
        self.changed = True
        self.factsheet_requested = False
        self.new_pose: Pose | None = None  # initPosition: the agent moves the robot there
        self._cancelling: ActionRun | None = None
        self.map_id = "factory"  # the mapId it reports (the master's roadmap names it)
        self.pose: Pose | None = None  # where the robot stands, set by the agent each cycle

    # -- what the master sends ---------------------------------------------------------------

    def on_order(self, payload: bytes) -> None:
        """Accept, stitch, ignore or reject an order (spec Figure 8); a rejection is an error in the state."""
        try:
            order = decode(payload, "order", self.version)
        except MessageError as error:
            self._error("validationError", f"order rejected: {error}", "WARNING", [("topic", "order")])
            return
        if order["orderId"] != self.order_id:
            if self._busy():
                self._reject(order, "orderError", f"still executing order {self.order_id}: cancel it first")
                return
            first = order["nodes"][0]
            if not self._reachable(first):
                self._reject(order, "noRouteError", f"start node {first['nodeId']} is not where the vehicle stands")
                return
            self._take(order, fresh=True)
            return
        if order["orderUpdateId"] < self.order_update_id:
            self._reject(order, "orderUpdateError", f"orderUpdateId {order['orderUpdateId']} is older than {self.order_update_id}")
            return
        if order["orderUpdateId"] == self.order_update_id:
            return  # an identical resend (§6.6.4.3): ignored
        first = order["nodes"][0]
        decision = self._decision_point()
        if (first["nodeId"], first["sequenceId"]) != decision:
            self._reject(order, "orderUpdateError", f"update starts at {first['nodeId']}/{first['sequenceId']}, "
                         f"not at the last base node {decision[0]}/{decision[1]}")
            return
        self._take(order, fresh=False)

    def on_instant_actions(self, payload: bytes) -> None:
        try:
            message = decode(payload, "instantActions", self.version)
        except MessageError as error:
            if "'actions' is a required property" not in str(error):
                self._error("validationError", f"instant actions rejected: {error}", "WARNING", [("topic", "instantActions")])
                return
            from softplc.protocols.vda5050.validation import parse_json

            message = parse_json(payload)  # vda-5050-lib's masters name the list `instantActions`
        for item in instant_actions_of(message):
            if not isinstance(item.get("actionId"), str) or not isinstance(item.get("actionType"), str):
                self._error("validationError", "an instant action without actionId or actionType", "WARNING",
                            [("topic", "instantActions")])
                continue
            self._instant(ActionRun(item["actionId"], item["actionType"], str(item.get("blockingType", "NONE")),
                                    parameters(item), instant=True))
        self.changed = True

    # -- each control cycle ----------------------------------------------------------------------

    def target(self, pose: Pose) -> tuple[float, float] | None:
        """Where to drive now: the next released node; None to stand still."""
        if self.paused or self._cancelling is not None or self._blocked():
            return None
        for waypoint in self.nodes:
            if not waypoint.released:
                return None  # the decision point is reached: wait for the base to grow
            if waypoint.x is not None and waypoint.y is not None:
                return waypoint.x, waypoint.y
        return None

    def step(self, now: float, pose: Pose, moving: bool) -> None:
        """Traverse the nodes the robot reached, run and finish actions, finish a cancel once it stands."""
        while self.nodes and self.nodes[0].released and not self._blocked() and not self.paused:
            waypoint = self.nodes[0]
            if waypoint.x is not None and waypoint.y is not None and math.hypot(pose.x - waypoint.x, pose.y - waypoint.y) > waypoint.deviation:
                break
            self._traverse(waypoint, now)
        for run in self.actions.values():
            if run.status == "RUNNING" and now >= run.ends_at and not self.paused:
                self._finish(run)
        if self._cancelling is not None and not moving:
            self._cancelling.status = "FINISHED"
            self._cancelling = None
            self.changed = True

    def state(self, pose: Pose | None, speed: float, turn_rate: float, battery: float = 100.0) -> dict[str, Any]:
        """The state message's body (the agent adds the header)."""
        body: dict[str, Any] = {
            "orderId": self.order_id, "orderUpdateId": self.order_update_id,
            "lastNodeId": self.last_node_id, "lastNodeSequenceId": self.last_node_sequence_id,
            "nodeStates": [{"nodeId": w.node_id, "sequenceId": w.sequence_id, "released": w.released} for w in self.nodes],
            "edgeStates": [{"edgeId": e, "sequenceId": s, "released": r} for e, s, r in self.edges],
            "driving": bool(speed or turn_rate), "paused": self.paused, "newBaseRequest": False,
            "actionStates": [self._action_state(run) for run in self.actions.values()],
            "batteryState": {"batteryCharge": battery, "charging": False},
            "operatingMode": "AUTOMATIC", "errors": list(self.errors), "loads": list(self.loads),
            "safetyState": {"eStop": "NONE", "fieldViolation": False},
            "velocity": {"vx": speed, "vy": 0.0, "omega": turn_rate},
        }
        if pose is not None:
            body["agvPosition"] = {"positionInitialized": True, "x": pose.x, "y": pose.y,
                                   "theta": math.atan2(math.sin(pose.heading), math.cos(pose.heading)), "mapId": self.map_id}
        if self.version != "2.0":
            body["maps"] = [{"mapId": self.map_id, "mapVersion": "1", "mapStatus": "ENABLED"}]
        return body

    # -- inside --------------------------------------------------------------------------------------

    def _busy(self) -> bool:
        return bool(self.nodes) or any(run.status not in ("FINISHED", "FAILED") for run in self.actions.values() if not run.instant)

    def _blocked(self) -> bool:
        """A SOFT or HARD action is running: the vehicle may not drive (§6.12)."""
        return any(run.status in ("INITIALIZING", "RUNNING", "PAUSED") and run.blocking != "NONE" for run in self.actions.values())

    def _decision_point(self) -> tuple[str, int]:
        base = [w for w in self.nodes if w.released]
        if base:
            return base[-1].node_id, base[-1].sequence_id
        return self.last_node_id, self.last_node_sequence_id

    def _reachable(self, node: dict[str, Any]) -> bool:
        position = node.get("nodePosition")
        if position is None or self.pose is None:
            return node["nodeId"] == self.last_node_id or not self.last_node_id
        deviation = position.get("allowedDeviationXY") or DEFAULT_DEVIATION
        return math.hypot(self.pose.x - position["x"], self.pose.y - position["y"]) <= max(deviation, DEFAULT_DEVIATION)

    def _take(self, order: dict[str, Any], *, fresh: bool) -> None:
        nodes, edges = order["nodes"], order["edges"]
        if fresh:
            self.nodes, self.edges = [], []
            self.actions = {key: run for key, run in self.actions.items() if run.instant and run.status == "RUNNING"}
        else:
            # The base is kept; the old horizon goes; the stitching node is already ours (in nodeStates, or lastNode).
            self.nodes = [w for w in self.nodes if w.released]
            self.edges = [e for e in self.edges if e[2]]
            if self.nodes or (nodes[0]["nodeId"], nodes[0]["sequenceId"]) == (self.last_node_id, self.last_node_sequence_id):
                nodes = nodes[1:]
        self.order_id, self.order_update_id = order["orderId"], order["orderUpdateId"]
        self.errors = [error for error in self.errors if error["errorType"] not in ("validationError", "orderError", "noRouteError",
                                                                                     "orderUpdateError")]
        for item in nodes:
            position = item.get("nodePosition") or {}
            ids = []
            for action in item["actions"]:
                self.actions[action["actionId"]] = ActionRun(action["actionId"], action["actionType"], action["blockingType"],
                                                             parameters(action))
                ids.append(action["actionId"])
            self.nodes.append(Waypoint(item["nodeId"], item["sequenceId"], item["released"], position.get("x"), position.get("y"),
                                       max(position.get("allowedDeviationXY") or DEFAULT_DEVIATION, 0.05), ids))
        self.edges += [(item["edgeId"], item["sequenceId"], item["released"]) for item in edges]
        self.changed = True

    def _traverse(self, waypoint: Waypoint, now: float) -> None:
        self.nodes.pop(0)
        self.last_node_id, self.last_node_sequence_id = waypoint.node_id, waypoint.sequence_id
        self.edges = [edge for edge in self.edges if edge[1] > waypoint.sequence_id]
        for action_id in waypoint.actions:
            run = self.actions.get(action_id)
            if run is not None and run.status == "WAITING":
                self._start(run, now)
        self.changed = True

    def _start(self, run: ActionRun, now: float) -> None:
        if run.type not in NODE_ACTIONS:
            self._fail(run, f"action {run.type} is not supported by this vehicle")
            return
        if run.type == "pick" and len(self.loads) >= self.load_capacity:
            self._fail(run, "load already picked")
            return
        if run.type == "drop" and not self.loads:
            self._fail(run, "no load to drop")
            return
        duration = run.params.get("duration", ACTION_SECONDS)
        run.status = "RUNNING"
        run.ends_at = now + (float(duration) if isinstance(duration, (int, float)) and not isinstance(duration, bool) else ACTION_SECONDS)

    def _finish(self, run: ActionRun) -> None:
        run.status = "FINISHED"
        if run.type == "pick":
            self.loads.append({"loadId": str(run.params.get("loadId", run.id)), "loadType": str(run.params.get("loadType", ""))})
        elif run.type == "drop" and self.loads:
            self.loads.pop()
        run.result = f"{run.type} finished"
        self.changed = True

    def _fail(self, run: ActionRun, why: str) -> None:
        run.status, run.result = "FAILED", why
        self._error("actionError", why, "WARNING", [("actionId", run.id)])

    def _instant(self, run: ActionRun) -> None:
        self.actions[run.id] = run
        if run.type == "cancelOrder":
            if not self._busy():
                run.status = "FAILED"
                self._error("noOrderToCancel", "there is no order to cancel", "WARNING", [("actionId", run.id)])
                return
            for other in self.actions.values():
                if not other.instant and other.status not in ("FINISHED", "FAILED"):
                    other.status = "FAILED"
            self.nodes, self.edges = [], []
            run.status = "RUNNING"  # until the vehicle stands (§6.6.3)
            self._cancelling = run
        elif run.type in ("startPause", "stopPause"):
            self.paused = run.type == "startPause"
            run.status = "FINISHED"
        elif run.type == "initPosition":
            params = run.params
            try:
                self.new_pose = Pose(float(params["x"]), float(params["y"]), float(params.get("theta", 0.0)))
            except (KeyError, TypeError, ValueError):
                self._fail(run, "initPosition needs numbers x, y (and theta)")
                return
            self.last_node_id = str(params.get("lastNodeId", ""))
            self.last_node_sequence_id = 0
            run.status = "FINISHED"
        elif run.type == "factsheetRequest":
            self.factsheet_requested = True
            run.status = "FINISHED"
        elif run.type == "stateRequest":
            run.status = "FINISHED"
        else:
            self._fail(run, f"instant action {run.type} is not supported by this vehicle")

    def _reject(self, order: dict[str, Any], kind: str, why: str) -> None:
        self._error(kind, why, "WARNING", [("orderId", order["orderId"]), ("orderUpdateId", str(order["orderUpdateId"]))])

    def _error(self, kind: str, description: str, level: str, references: list[tuple[str, str]]) -> None:
        error = {"errorType": kind, "errorLevel": level, "errorDescription": description[:500],
                 "errorReferences": [{"referenceKey": key, "referenceValue": value} for key, value in references]}
        self.errors = [item for item in self.errors if item["errorType"] != kind] + [error]
        self.changed = True

    @staticmethod
    def _action_state(run: ActionRun) -> dict[str, Any]:
        state = {"actionId": run.id, "actionType": run.type, "actionStatus": run.status}
        if run.result:
            state["resultDescription"] = run.result
        return state
