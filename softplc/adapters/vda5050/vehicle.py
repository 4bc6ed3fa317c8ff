"""The master's view of one vehicle: its last state, liveness, errors, and the robot tags it fills.

A vehicle is alive while its states are fresh (`lost_after`), not because its `connection`
topic says ONLINE (the spec: do not judge health by it; vda-5050-lib does not even say ONLINE
again after a reconnect). While it is lost, or the broker is, its pose tags are BAD quality,
`rNN_online` is false and `rNN_navstate` says `offline`. A state fills the same tags as any
robot's driver does (xpos, ypos, heading, speed, navstate, navreason, route, online) plus the
VDA 5050 ones (`_sys.vda5050.<id>.*`: battery, mode, e-stop, errors, connection…).
"""

from __future__ import annotations

import logging
import math
from typing import Any

from softplc.adapters.vda5050.orders import Trip
from softplc.core.tagdb import Origin, TagDatabase
from softplc.core.tags import Quality
from softplc.protocols.vda5050.messages import FactsheetSummary, Headers, VehicleState
from softplc.robotics.peers import encode_route
from softplc.robotics.roadmap import Roadmap
from softplc.robotics.robots import RobotSpec

log = logging.getLogger(__name__)

POSE_TAGS = ("xpos", "ypos", "heading", "speed")


class VehicleLink:
    """See the module docstring."""

    def __init__(self, spec: RobotSpec, version: str, db: TagDatabase) -> None:
        assert spec.vehicle is not None
        self.spec = spec
        self.id = spec.id
        self.identity = spec.vehicle
        self.db = db
        self.headers = Headers(version, spec.vehicle.manufacturer, spec.vehicle.serial_number)
        self.state: VehicleState | None = None
        self.last_state_at = -math.inf
        self.states = 0
        self.bad_messages = 0
        self.alive = False
        self.connection = ""
        self.factsheet: FactsheetSummary | None = None
        self.factsheet_requested = False
        self.trip: Trip | None = None
        self.previous_orders: set[str] = set()  # ours, finished or replaced: a state may still name them
        self.goal: tuple[float, float] = (float(db.value(f"{spec.id}_xgoal")), float(db.value(f"{spec.id}_ygoal")))
        self.cancel_id = ""  # a cancelOrder in flight
        self.foreign_order = ""  # an order of someone else the vehicle reported
        self.note = ""  # the master's own complaint about this vehicle (bad messages), shown with its errors
        self.origin = Origin(f"vda5050:{spec.id}", role=None)
        self.prefix = f"_sys.vda5050.{spec.id}"
        self._last: dict[str, Any] = {}

    # -- tags ---------------------------------------------------------------------------------------

    def write(self, **values: Any) -> None:
        """Robot tags (rNN_NAME) and VDA 5050 tags (_sys.vda5050.<id>.NAME, names given with a leading '_'), changed ones only."""
        items = []
        for key, value in values.items():
            name = f"{self.prefix}.{key[1:]}" if key.startswith("_") else f"{self.id}_{key}"
            if name in self.db and self._last.get(name, object()) != value:
                self._last[name] = value
                items.append((name, value))
        if items:
            for rejected in self.db.submit(items, self.origin):
                if rejected is not None:
                    log.warning("vehicle %s: %s", self.id, rejected)

    def go_offline(self, why: str, *, quiet: bool = False) -> None:
        """Lost (no fresh state, connection broken, broker gone): pose tags BAD, online false, navstate offline."""
        if self.alive and not quiet:
            log.warning("VDA 5050 vehicle %s (%s/%s) is lost: %s; its tags are BAD until it reports again", self.id,
                        self.identity.manufacturer, self.identity.serial_number, why)
        self.alive = False
        self.write(online=False, navstate="offline", navreason=why, speed=0.0)
        names = [f"{self.id}_{name}" for name in POSE_TAGS if f"{self.id}_{name}" in self.db]
        self.db.submit_quality(names, Quality.BAD, self.origin)
        self._last = {name: value for name, value in self._last.items() if not name.startswith(f"{self.id}_") or
                      name.rsplit("_", 1)[-1] not in POSE_TAGS}  # re-sent with GOOD quality on the next state

    def show_state(self, state: VehicleState, roadmap: Roadmap) -> None:
        """A fresh, checked state: pose, motion and the vehicle's own errors into the tags."""
        values: dict[str, Any] = {"online": True, "speed": round(state.speed, 4)}
        if state.position is not None:
            x, y, theta = state.position
            values.update(xpos=x, ypos=y, heading=theta)
        values.update(_battery=state.battery_charge, _mode=state.operating_mode, _estop=state.e_stop, _paused=state.paused,
                      _error=self.error_text(state))
        trip = self.trip
        if trip is not None and not trip.done and state.position is not None:
            remaining = [roadmap.nodes[node_id] for node_id, _, _ in state.node_states if node_id in roadmap.nodes]
            values["route"] = encode_route([(state.position[0], state.position[1]), *[(n.x, n.y) for n in remaining]])
        else:
            values["route"] = ""
        self.write(**values)

    def error_text(self, state: VehicleState | None) -> str:
        parts = [error.text for error in state.errors] if state is not None else []
        if self.note:
            parts.append(self.note)
        return "; ".join(parts)[:1000]

    def show_trip(self) -> None:
        trip = self.trip
        self.write(_order=f"{trip.order_id}/{trip.update_id}" if trip is not None else "",
                   _base=" ".join(trip.base) if trip is not None and not trip.done else "",
                   _horizon=" ".join(trip.horizon) if trip is not None and not trip.done else "",
                   _resends=trip.resends if trip is not None else 0)

    # -- what the master makes of a state ----------------------------------------------------------------

    def here(self, roadmap: Roadmap) -> str:
        """The node the vehicle stands on or last passed: its lastNodeId when that is near, else the node nearest to it."""
        state = self.state
        if state is None or state.position is None:
            return state.last_node_id if state is not None and state.last_node_id in roadmap.nodes else ""
        x, y, _ = state.position
        if state.last_node_id in roadmap.nodes:
            known = roadmap.nodes[state.last_node_id]
            if math.hypot(known.x - x, known.y - y) <= max(1.0, 2 * roadmap.deviation):
                return known.id
        return roadmap.nearest(x, y).id

    def busy_with_foreign_order(self) -> bool:
        state = self.state
        ours = {self.trip.order_id} if self.trip is not None else set()
        return state is not None and state.order_id not in ours and bool(state.node_states)
