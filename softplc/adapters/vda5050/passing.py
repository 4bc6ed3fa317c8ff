"""Traffic decisions of the master control: growing each base, breaking deadlocks, sending idle vehicles aside.

softplc.adapters.vda5050.traffic keeps who holds which node and lane; these functions decide, once per tick,
on the master control's state (`control`: softplc.adapters.vda5050.control.MasterControl):

- `grow_bases`: each vehicle's base grows node by node, up to `lookahead` past the node it last passed, onto
  what nobody holds; every growth is an order update to send.
- `resolve_deadlocks`: in each circle of vehicles waiting for each other one goes round the others, or, where
  there is no way round (a station at the end of a spur met head-on), steps aside to a free node off their ways
  and comes back (a passing place). A re-routed vehicle gets REROUTE_PATIENCE to move before it is re-routed again.
- `make_way`: an idle vehicle standing where another has waited for MAKE_WAY_AFTER goes to a free node nearby.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from softplc.adapters.vda5050.orders import Trip

log = logging.getLogger(__name__)

REROUTE_PATIENCE = 5.0  # s a re-routed vehicle gets to move before it is re-routed again
MAKE_WAY_AFTER = 2.0  # s another waits before an idle vehicle in its way is sent aside (and between two such moves)


def grow_bases(control: Any) -> None:
    """Each vehicle's base onto the free nodes and lanes ahead (an order update when it grew)."""
    for link in control.links.values():
        trip = link.trip
        if trip is None or not link.alive:
            continue
        state = link.state
        position = trip.position(state.last_node_id, state.last_node_sequence_id) if state is not None and \
            state.order_id == trip.order_id else 0
        released = control.traffic.extend(link.id, trip.route, trip.released, max(position, 0), control.settings.lookahead)
        if released != trip.released:
            trip.released = released
            trip.body = None  # an update is due
            link.show_trip()


def resolve_deadlocks(control: Any, now: float) -> None:
    """Break each circle of vehicles waiting for each other: one goes round the others, or, where there is no way
    round (a station at the end of a spur, met head-on), steps aside to a free node off their way and comes back."""
    for cycle in control.traffic.deadlocks():
        for victim in sorted(cycle, reverse=True):
            link = control.links.get(victim)
            trip = link.trip if link is not None else None
            if trip is None or (trip.rerouted[1] == trip.passed and now - trip.rerouted[0] < REROUTE_PATIENCE):
                continue  # re-routed a moment ago and not moved since: give that a chance, or try another
            others = [other for other in cycle if other != victim]
            tail = _detour(control, trip, others) or _retreat(control, trip, others)
            if tail is None:
                continue
            trip.route = trip.route[: trip.released + 1] + tail[1:]
            trip.body = None
            trip.rerouted = (now, trip.passed)
            control.traffic.waits.pop(victim, None)
            control.deadlocks_broken += 1
            log.info("deadlock of %s broken: %s now goes %s", " ↔ ".join(cycle), victim, " ".join(tail))
            break
        else:
            for name in cycle:
                if name in control.links:
                    control.links[name].write(navreason=f"deadlock with {', '.join(o for o in cycle if o != name)}: no way round")


def _detour(control: Any, trip: Trip, others: list[str]) -> list[str] | None:
    """A way from the decision point to the goal round the nodes the others hold; None if none, or no different one."""
    blocked = set().union(*(control.traffic.nodes_of(other) for other in others))
    tail = control.roadmap.route(trip.route[trip.released], trip.goal_node, avoid=frozenset(blocked))
    return tail if tail is not None and tail != trip.route[trip.released:] else None


def _retreat(control: Any, trip: Trip, others: list[str]) -> list[str] | None:
    """To the nearest free node off the others' ways, then on to the goal (a passing place)."""
    their_ways: set[str] = set()
    for other in others:
        other_trip = control.links[other].trip if other in control.links else None
        if other_trip is not None:
            their_ways.update(other_trip.route[other_trip.passed:])
    held = control.traffic.holder_nodes()
    here = trip.route[trip.released]
    origin = control.roadmap.nodes[here]
    candidates = sorted((node for node in control.roadmap.nodes.values() if node.id not in their_ways and node.id not in held),
                        key=lambda node: math.hypot(node.x - origin.x, node.y - origin.y))
    for refuge in candidates[:8]:
        there = control.roadmap.route(here, refuge.id, avoid=frozenset(held - {here}))
        back = control.roadmap.route(refuge.id, trip.goal_node)
        if there is not None and back is not None:
            return there + back[1:]
    return None


def make_way(control: Any, now: float) -> None:
    """An idle vehicle (no trip, not busy in the plant) that another has waited for over MAKE_WAY_AFTER goes to a free node nearby."""
    if not control.settings.make_way:
        return
    waits = control.traffic.waits
    since = control.waiting_since
    for name in [name for name in since if name not in waits]:
        del since[name]
    for name, wait in list(waits.items()):
        first = since.get(name)
        if first is None or first[0] != wait.resource:
            since[name] = (wait.resource, now)
            continue
        blocker = control.links.get(wait.holder)
        waiting = control.links.get(name)
        if now - first[1] < MAKE_WAY_AFTER or blocker is None or waiting is None or waiting.trip is None or not blocker.alive \
                or blocker.trip is not None or now - control.moved_aside.get(blocker.id, -math.inf) < MAKE_WAY_AFTER:
            continue
        db = control.db
        if bool(db.value(f"{blocker.id}_status")) or (f"{blocker.id}_currloc" in db and db.value(f"{blocker.id}_currloc")):
            continue  # busy in the plant (loading, unloading): it stays
        control.moved_aside[blocker.id] = now
        here = blocker.here(control.roadmap)
        held = control.traffic.holder_nodes()
        keep_clear = set(waiting.trip.route) | held
        origin = control.roadmap.nodes[here]
        refuges = sorted((node for node in control.roadmap.nodes.values() if node.id not in keep_clear),
                         key=lambda node: math.hypot(node.x - origin.x, node.y - origin.y))
        for refuge in refuges[:5]:
            if control.roadmap.route(here, refuge.id, avoid=frozenset(held - {here})) is not None:
                log.info("%s waits for %s, which stands idle at %s: sending it aside to %s", name, blocker.id, here, refuge.id)
                control.start(blocker, (refuge.x, refuge.y), now, make_way=True)
                break
