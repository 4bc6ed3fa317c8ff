"""Traffic control by reservation: no two vehicles ever hold the same node or lane at once.

A vehicle holds the node it stands on and everything released to it (its base). The base grows
only onto resources nobody else holds (`extend`), and what the vehicle has passed is given back
(`release_behind`). A lane is one resource for both its directions: two vehicles meeting
head-on on it would collide. A vehicle that cannot grow its base waits; `deadlocks()` finds the
circles of vehicles waiting for each other, which the master breaks by re-routing one of them
around the others (adapter.py), and an idle vehicle in another's way can be sent aside.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from softplc.robotics.roadmap import Roadmap


def node_resource(node_id: str) -> str:
    return f"node:{node_id}"


def lane_resource(a: str, b: str) -> str:
    first, second = sorted((a, b))
    return f"lane:{first}|{second}"


@dataclass(frozen=True)
class Wait:
    """What keeps a vehicle from growing its base: a resource and who holds it."""

    resource: str
    holder: str

    @property
    def text(self) -> str:
        kind, name = self.resource.split(":", 1)
        return f"{kind} {name.replace('|', '–')} held by {self.holder}"


class Reservations:
    """Who holds which node and lane (see the module docstring)."""

    def __init__(self, roadmap: Roadmap) -> None:
        self.roadmap = roadmap
        self.holder: dict[str, str] = {}
        self.held: dict[str, set[str]] = {}
        self.waits: dict[str, Wait] = {}
        self.conflicts = 0  # claims of a resource someone else held: must stay 0 (the benchmark counts it)

    def claim(self, vehicle: str, resources: Iterable[str]) -> bool:
        """Take all of `resources` for `vehicle`, or none if any is someone else's."""
        resources = list(resources)
        for resource in resources:
            holder = self.holder.get(resource)
            if holder is not None and holder != vehicle:
                self.waits[vehicle] = Wait(resource, holder)
                return False
        mine = self.held.setdefault(vehicle, set())
        for resource in resources:
            self.holder[resource] = vehicle
            mine.add(resource)
        self.waits.pop(vehicle, None)
        return True

    def step_resources(self, route: list[str], index: int) -> list[str]:
        """The lane into route[index] and the node itself."""
        return [lane_resource(route[index - 1], route[index]), node_resource(route[index])]

    def extend(self, vehicle: str, route: list[str], released: int, position: int, lookahead: int) -> int:
        """The new decision point: grown node by node up to `lookahead` past `position` while the way is free."""
        target = min(len(route) - 1, max(position, 0) + lookahead)
        while released < target and self.claim(vehicle, self.step_resources(route, released + 1)):
            released += 1
        if released >= target:
            self.waits.pop(vehicle, None)
        return released

    def release_behind(self, vehicle: str, route: list[str], position: int, released: int) -> None:
        """Give back the nodes and lanes before route[position] (the vehicle has passed them), but none its base still
        needs: a route that comes back (a passing place) meets a node or lane again further on."""
        keep = {node_resource(node) for node in route[position: released + 1]}
        keep |= {lane_resource(route[i], route[i + 1]) for i in range(position, released)}
        passed = [node_resource(node) for node in route[:position]]
        passed += [lane_resource(route[i], route[i + 1]) for i in range(position)]
        self.release(vehicle, [resource for resource in passed if resource not in keep])

    def release(self, vehicle: str, resources: Iterable[str]) -> None:
        mine = self.held.get(vehicle, set())
        for resource in resources:
            if self.holder.get(resource) == vehicle:
                del self.holder[resource]
                mine.discard(resource)

    def release_all(self, vehicle: str, keep_node: str | None = None) -> None:
        """Everything but the node it stands on (which it claims if free)."""
        self.release(vehicle, list(self.held.get(vehicle, ())))
        self.waits.pop(vehicle, None)
        if keep_node is not None:
            self.claim(vehicle, [node_resource(keep_node)])

    def stand(self, vehicle: str, node_id: str) -> bool:
        """The vehicle stands on `node_id` (its start, or where it stopped): hold that node; False if another holds it."""
        resource = node_resource(node_id)
        holder = self.holder.get(resource)
        if holder is not None and holder != vehicle:
            self.conflicts += 1
            return False
        self.claim(vehicle, [resource])
        return True

    def holder_nodes(self) -> set[str]:
        """Every node somebody holds."""
        return {resource.split(":", 1)[1] for resource in self.holder if resource.startswith("node:")}

    def nodes_of(self, vehicle: str) -> set[str]:
        return {resource.split(":", 1)[1] for resource in self.held.get(vehicle, ()) if resource.startswith("node:")}

    def deadlocks(self) -> list[list[str]]:
        """Circles in the wait-for graph (each a list of vehicles, each waiting for the next)."""
        found: list[list[str]] = []
        seen: set[str] = set()
        for start in sorted(self.waits):
            path: list[str] = []
            here: str | None = start
            while here is not None and here not in path and here not in seen:
                path.append(here)
                wait = self.waits.get(here)
                here = wait.holder if wait is not None else None
            if here is not None and here in path:
                cycle = path[path.index(here):]
                if sorted(cycle) not in [sorted(known) for known in found]:
                    found.append(cycle)
            seen.update(path)
        return found
