"""The master control's decisions: goals become trips, states acknowledge or reject them, traffic releases the base.

`MasterControl` holds no connection: `on_state`, `on_connection` and `tick` change what it knows
and put the messages to send into `outbox` (vehicle, topic, body); adapter.py publishes them.
Faults are handled as users of other masters asked (issue 24): liveness from fresh states; an
order not acknowledged within `ack_timeout` is sent again identically; a vehicle that lost its
order (a reboot) gets a fresh one, never an endless cancel; a rejection or an error becomes the
robot's `failed` state and an alarm with the vehicle's own text; a lost vehicle's task is given
back to the dispatcher (rNN_currloc and rNN_tcurr reset) so another robot takes it.
"""

from __future__ import annotations

import logging
import math
import uuid
from typing import Any

from softplc.adapters.vda5050 import passing
from softplc.adapters.vda5050.orders import Trip, load_actions
from softplc.adapters.vda5050.settings import VdaSettings
from softplc.adapters.vda5050.traffic import Reservations
from softplc.adapters.vda5050.vehicle import VehicleLink
from softplc.core.tagdb import TagDatabase
from softplc.protocols.vda5050 import topics
from softplc.protocols.vda5050.messages import VehicleState, action
from softplc.robotics.arrival import within_goal
from softplc.robotics.roadmap import Roadmap

log = logging.getLogger(__name__)

REJECTIONS = ("validationError", "orderError", "orderUpdateError", "noRouteError")
TO_SOURCE, TO_DESTINATION = 1, 3
REROUTE_PATIENCE = 5.0  # s a re-routed vehicle gets to move before it is re-routed again  # the motion sequencer's currloc on the way to a station (programs/motion_sequencer.py)


class MasterControl:
    """See the module docstring."""

    def __init__(self, roadmap: Roadmap, settings: VdaSettings, links: dict[str, VehicleLink], db: TagDatabase) -> None:
        self.roadmap = roadmap
        self.settings = settings
        self.links = links
        self.db = db
        self.traffic = Reservations(roadmap)
        self.outbox: list[tuple[VehicleLink, str, dict[str, Any]]] = []
        self.session = uuid.uuid4().hex[:6]  # in every orderId: a restarted master never repeats one a vehicle still holds
        self._orders = 0
        self.deadlocks_broken = 0
        self.broker_up = False
        self.waiting_since: dict[str, tuple[str, float]] = {}  # vehicle → (what it waits for, since when)
        self.moved_aside: dict[str, float] = {}  # idle vehicle → when it was last sent aside
        # Goals are looked at when their tags change (and when a vehicle comes back), not every tick for every vehicle.
        self.touched: set[str] = set(links)
        self._goal_tags = {f"{name}_{tag}": name for name in links for tag in ("xgoal", "ygoal", "status")}
        self.close = db.on_change(self._changed)

    def _changed(self, tags: Any) -> None:
        goal_tags = self._goal_tags
        for tag in tags:
            name = goal_tags.get(tag.name)
            if name is not None:
                self.touched.add(name)

    # -- what vehicles say ---------------------------------------------------------------------------------

    def on_state(self, link: VehicleLink, state: VehicleState, now: float) -> None:
        link.state, link.last_state_at, link.states = state, now, link.states + 1
        if link.cancel_id and state.action_states.get(link.cancel_id) in ("FINISHED", "FAILED"):
            link.cancel_id = ""  # the cancel is through: the vehicle takes orders again
        if not link.alive:
            link.alive = True
            log.info("VDA 5050 vehicle %s (%s/%s) reports", link.id, link.identity.manufacturer, link.identity.serial_number)
            self.touched.add(link.id)  # a goal written while it was away is taken up now
            if link.trip is None:
                link.write(navstate="idle", navreason="")  # back: it takes trips again
            here = link.here(self.roadmap)
            if here and link.trip is None:
                # What it held while away (it may have driven its base meanwhile) goes; where it stands now stays.
                self.traffic.release_all(link.id)
                self.traffic.stand(link.id, here)
            if link.factsheet is None and not link.factsheet_requested:  # vda-5050-lib sends one only when asked
                link.factsheet_requested = True
                self._orders += 1
                self.outbox.append((link, topics.INSTANT_ACTIONS,
                                    {"actions": [action("factsheetRequest", f"{link.id}.{self.session}.factsheet.{self._orders}")]}))
        trip = link.trip
        ours = {trip.order_id} if trip is not None else set()
        if state.order_id and state.order_id not in ours | link.previous_orders and state.order_id != link.foreign_order:
            link.foreign_order = state.order_id
            log.warning("VDA 5050 vehicle %s reports order %r, which this master never sent", link.id, state.order_id)
        if trip is not None:
            self._follow(link, trip, state, now)
        link.show_state(state, self.roadmap)
        link.show_trip()

    def on_connection(self, link: VehicleLink, connection_state: str) -> None:
        link.connection = connection_state
        link.write(_connection=connection_state)
        if connection_state in ("CONNECTIONBROKEN", "OFFLINE") and link.alive:
            self.lose(link, f"connection {connection_state}")

    def lose(self, link: VehicleLink, why: str, *, quiet: bool = False) -> None:
        """A vehicle gone quiet: BAD tags; its trip ends, and its task goes back to the dispatcher (`quiet`: no log line)."""
        link.go_offline(why, quiet=quiet)
        trip = link.trip
        if trip is not None:
            link.previous_orders.add(trip.order_id)
            link.trip = None
            # Its reservations stay: a vehicle out of reach drives on to the end of its base (spec §6.2), and nobody
            # may drive into where it might be. They go when it reports again, from where it then stands.
            self.traffic.waits.pop(link.id, None)
            if not trip.make_way:
                if not quiet:
                    log.warning("vehicle %s lost on its way to (%g, %g): its task goes back to the dispatcher", link.id, *trip.goal)
                resets = {"status": False, "currloc": 0, "tcurr": 0}
                link.write(**{key: value for key, value in resets.items() if f"{link.id}_{key}" in self.db})
            link.show_trip()

    def broker(self, up: bool) -> None:
        self.broker_up = up
        if not up:
            alive = [link for link in self.links.values() if link.alive]
            for link in self.links.values():
                self.lose(link, "the MQTT broker is unreachable", quiet=True)  # one line for all of them
            if alive:
                log.warning("vda5050: the MQTT broker is unreachable: %d vehicles out of reach, their tags BAD and the tasks of "
                            "those on a trip given back to the dispatcher", len(alive))

    # -- each tick -----------------------------------------------------------------------------------------------

    def tick(self, now: float, *, liveness: bool = True) -> None:
        """Liveness (unless states wait unread: they may be fresh), goals, traffic, and what to send."""
        for link in self.links.values():
            if liveness and link.alive and now - link.last_state_at > self.settings.lost_after:
                self.lose(link, f"no state for {self.settings.lost_after:g} s")
        touched, self.touched = self.touched, set()
        for name in touched:
            link = self.links[name]
            if link.alive:
                self._goal(link, now)
            else:
                self.touched.add(name)  # taken up when it reports
        passing.grow_bases(self)
        passing.resolve_deadlocks(self, now)
        passing.make_way(self, now)
        for link in self.links.values():
            if link.alive and link.trip is not None:
                self._send(link, link.trip, now)

    def _goal(self, link: VehicleLink, now: float) -> None:
        name = link.id
        goal = (float(self.db.value(f"{name}_xgoal")), float(self.db.value(f"{name}_ygoal")))
        busy = bool(self.db.value(f"{name}_status"))
        trip = link.trip
        if math.dist(goal, link.goal) > 1e-6:
            link.goal = goal
            self.start(link, goal, now)
        elif busy and (trip is None or trip.make_way) and link.state is not None and link.state.position is not None:
            x, y, _ = link.state.position
            if within_goal(x, y, goal[0], goal[1]):
                link.write(status=False, navstate="arrived", navreason="")
            else:
                self.start(link, goal, now)  # asked again (a retry after a failure, or a goal written with status)

    def start(self, link: VehicleLink, goal: tuple[float, float], now: float, *, make_way: bool = False) -> None:
        """Send the vehicle to `goal` (the roadmap node nearest to it): a new order, or the running one extended."""
        if link.busy_with_foreign_order():
            self._cancel(link, now)  # once; the goal is taken up again when the vehicle is free
            link.goal = (math.nan, math.nan)
            self.touched.add(link.id)
            return
        goal_node = self.roadmap.nearest(*goal).id
        trip = link.trip
        kind = {TO_SOURCE: "pick", TO_DESTINATION: "drop"}.get(int(self.db.value(f"{link.id}_currloc")) if f"{link.id}_currloc" in self.db else 0, "")
        if make_way or not self.roadmap.nodes[goal_node].station:
            kind = ""
        if trip is not None and not trip.done and trip.update_id >= 0:
            tail = self.roadmap.route(trip.route[trip.released], goal_node)
            if tail is not None:  # stitched at the decision point: the base cannot change (§6.6.2)
                trip.route = trip.route[: trip.released + 1] + tail[1:]
                trip.goal, trip.make_way = goal, make_way
                trip.goal_actions = load_actions(kind, f"{trip.order_id}.{trip.update_id + 1}.{kind}", self.roadmap.load_handling)
                trip.sent_from = min(trip.sent_from, trip.released)
                trip.body = None  # a new message is due
                self._begin(link, make_way)
                return
        here = link.here(self.roadmap)
        route = self.roadmap.route(here, goal_node) if here else None
        if route is None:
            link.write(status=False, navstate="failed", navreason=f"no way on the roadmap from {here or 'nowhere'} to {goal_node}")
            return
        if trip is not None:
            link.previous_orders.add(trip.order_id)
        self._orders += 1
        order_id = f"{link.id}.{self.session}.{self._orders}"
        state = link.state
        distance = 0.0
        if state is not None and state.position is not None:
            node = self.roadmap.nodes[here]
            distance = math.hypot(node.x - state.position[0], node.y - state.position[1])
        link.trip = Trip(order_id, route, goal, load_actions(kind, f"{order_id}.{kind}", self.roadmap.load_handling),
                         first_deviation=max(self.roadmap.deviation, distance + 0.2), make_way=make_way,
                         old_errors={error.text for error in state.errors} if state is not None else set())
        self.traffic.release_all(link.id, keep_node=here)
        self._begin(link, make_way)

    def _begin(self, link: VehicleLink, make_way: bool) -> None:
        if not make_way:
            link.write(status=True, navstate="planning", navreason="")
        link.show_trip()

    # -- following a trip ------------------------------------------------------------------------------------------

    def _follow(self, link: VehicleLink, trip: Trip, state: VehicleState, now: float) -> None:
        if state.order_id == trip.order_id:
            trip.acknowledged_update = max(trip.acknowledged_update, state.order_update_id)
            link.write(_rejected="")
        rejection = self._rejection(trip, state)
        if rejection:
            self._fail(link, trip, rejection, rejected=True)
            return
        if state.order_id != trip.order_id:
            if trip.acknowledged_update >= 0:  # it had our order, and now has none (or another): it rebooted
                log.warning("vehicle %s no longer has order %s (it reports %r): sending a fresh order", link.id, trip.order_id,
                            state.order_id)
                link.trip = None
                link.previous_orders.add(trip.order_id)
                if not state.node_states:
                    self.start(link, trip.goal, now, make_way=trip.make_way)
            return
        position = trip.position(state.last_node_id, state.last_node_sequence_id)
        if position >= 0:
            trip.passed = position
            self.traffic.release_behind(link.id, trip.route, position, trip.released)
        ids = [item["actionId"] for item in trip.goal_actions]
        finished = all(state.action_states.get(action_id) in ("FINISHED", "FAILED") for action_id in ids)
        if position == len(trip.route) - 1 and trip.acknowledged and not state.node_states and finished:
            failed = [action_id for action_id in ids if state.action_states.get(action_id) == "FAILED"]
            trip.done = True
            link.previous_orders.add(trip.order_id)
            link.trip = None
            if not trip.make_way:
                if failed:
                    link.write(status=False, navstate="failed", navreason=f"{trip.goal_actions[0]['actionType']} failed: "
                               f"{link.error_text(state) or 'the vehicle gave no reason'}")
                else:
                    link.write(status=False, navstate="arrived", navreason="")
            return
        if not trip.make_way:
            waiting = self.traffic.waits.get(link.id)
            standing = position >= trip.released and not state.driving
            if waiting is not None and standing:
                link.write(navstate="blocked", navreason=f"waiting: {waiting.text}", _waiting=waiting.text)
            else:
                link.write(navstate="moving" if trip.acknowledged else "planning", navreason="", _waiting="")

    def _rejection(self, trip: Trip, state: VehicleState) -> str:
        """The vehicle's words when it refused our order: an error naming it, or a new order error while unacknowledged."""
        for error in state.errors:
            if error.reference("orderId") == trip.order_id:
                return error.text
            if not trip.acknowledged and error.type in REJECTIONS and error.text not in trip.old_errors and error.reference("orderId") is None:
                return error.text
        return ""

    def _fail(self, link: VehicleLink, trip: Trip, why: str, *, rejected: bool) -> None:
        log.warning("vehicle %s rejected order %s: %s", link.id, trip.order_id, why)
        link.previous_orders.add(trip.order_id)
        link.trip = None
        self.traffic.release_all(link.id, keep_node=link.here(self.roadmap) or None)
        link.write(status=False, navstate="failed", navreason=why[:300], **({"_rejected": why} if rejected else {}))
        link.show_trip()

    # -- sending -------------------------------------------------------------------------------------------------------

    def _send(self, link: VehicleLink, trip: Trip, now: float) -> None:
        if trip.body is None and (trip.update_id < 0 or trip.acknowledged):
            body = trip.message(self.roadmap)
            trip.sent(body, now)
            self.outbox.append((link, topics.ORDER, body))
            link.show_trip()
        elif trip.body is not None and not trip.acknowledged and now - trip.sent_at >= self.settings.ack_timeout:
            trip.resends += 1
            trip.sent_at = now
            self.outbox.append((link, topics.ORDER, trip.body))  # identical: a vehicle that has it ignores it (§6.6.4.3)
            link.show_trip()

    def _cancel(self, link: VehicleLink, now: float) -> None:
        """Cancel an order this master did not give (a vehicle still busy with a previous master's order): once."""
        if not link.cancel_id:
            self._orders += 1
            link.cancel_id = f"{link.id}.{self.session}.cancel.{self._orders}"
            log.warning("vehicle %s is still busy with order %r, not its current one (a previous master's, or one given up while "
                        "it was out of reach): cancelling it", link.id, link.state.order_id if link.state else "")
            self.outbox.append((link, topics.INSTANT_ACTIONS, {"actions": [action("cancelOrder", link.cancel_id, "HARD")]}))

    def instant(self, link: VehicleLink, an_action: dict[str, Any]) -> None:
        """Queue one instant action for a vehicle (cancelOrder, startPause, stopPause, initPosition, factsheetRequest…)."""
        if an_action["actionType"] == "cancelOrder" and link.trip is not None:
            link.previous_orders.add(link.trip.order_id)
            make_way = link.trip.make_way
            link.trip = None
            link.cancel_id = an_action["actionId"]
            self.traffic.release_all(link.id, keep_node=link.here(self.roadmap) or None)
            if not make_way:  # like a robot whose trip failed: a new goal, or status set again, sends it off
                link.write(status=False, navstate="idle", navreason="order cancelled")
            link.show_trip()
        self.outbox.append((link, topics.INSTANT_ACTIONS, {"actions": [an_action]}))
