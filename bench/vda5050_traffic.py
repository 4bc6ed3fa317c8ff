"""Traffic control at scale: many VDA 5050 vehicles on one roadmap for ten simulated minutes, never two on a node or lane.

The master control's own decisions (softplc/adapters/vda5050/control.py: orders, reservations, deadlock
breaking, making way) drive simulated vehicles in one process on the simulated clock: each vehicle is our
vehicle's order logic (softplc/clients/robot_agent/vda5050/vehicle.py) on a point that drives straight along
the lanes at 1 m/s; every order and instant action goes to it as JSON through the schema checks, every state
comes back as JSON through the master's. No broker: this measures the traffic control, not MQTT
(bench/vda5050_fleet.py does that with vda-5050-lib's vehicles on mosquitto). Each free vehicle gets a new
random goal node; at every 0.1 s step the bench checks where the vehicles physically are: the node each
stands on, and the lane and end node of the edge each drives on.

Goal (issue 24): 0 reservation conflicts over 10 simulated minutes with 50 vehicles on one roadmap.

    .venv/bin/python bench/vda5050_traffic.py [--vehicles 50] [--minutes 10] [--columns 16 --rows 12] [--seed 1]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import random
import shutil
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc.adapters.vda5050.control import MasterControl  # noqa: E402
from softplc.adapters.vda5050.settings import VdaSettings  # noqa: E402
from softplc.adapters.vda5050.traffic import lane_resource, node_resource  # noqa: E402
from softplc.adapters.vda5050.vehicle import VehicleLink  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402
from softplc.clients.robot_agent.vda5050.vehicle import Vehicle  # noqa: E402
from softplc.config import load_config  # noqa: E402
from softplc.core.clock import SimClock  # noqa: E402
from softplc.protocols.vda5050.messages import Headers, VehicleState  # noqa: E402
from softplc.protocols.vda5050.validation import decode, problems  # noqa: E402
from softplc.robotics.roadmap import load_roadmap  # noqa: E402
from softplc.robotics.robots import Pose, load_robots  # noqa: E402

SPACING = 2.0  # m between grid nodes
SPEED = 1.0  # m/s
STEP = 0.1  # s


def write_plant(directory: Path, vehicles: int, columns: int, rows: int, rng: random.Random) -> list[str]:
    """A grid roadmap, `vehicles` robots on distinct nodes, and the plant that names them; the start nodes."""
    nodes = [(f"n{c}_{r}", c * SPACING + 1, r * SPACING + 1) for c in range(columns) for r in range(rows)]
    lanes = [(f"n{c}_{r}", f"n{c + 1}_{r}") for c in range(columns - 1) for r in range(rows)]
    lanes += [(f"n{c}_{r}", f"n{c}_{r + 1}") for c in range(columns) for r in range(rows - 1)]
    (directory / "roadmap.yaml").write_text("roadmap:\n  map_id: grid\n  deviation: 0.05\n  waypoints:\n" + "".join(
        f"    - {{id: {name}, x: {x}, y: {y}}}\n" for name, x, y in nodes) + "  lanes:\n" + "".join(
        f"    - {{from: {a}, to: {b}}}\n" for a, b in lanes))
    starts = rng.sample(nodes, vehicles)
    (directory / "robots.yaml").write_text("robots:\n" + "".join(
        f"  - {{id: v{index:03d}, driver: vda5050, vda5050: {{manufacturer: bench, serial_number: s{index:03d}}}, length_mm: 500, "
        f"width_mm: 500, height_mm: 500, load_capacity: 1, max_linear_speed: {SPEED}, max_angular_speed: 1, start: {{x: {x}, y: {y}}}}}\n"
        for index, (_, x, y) in enumerate(starts)))
    (directory / "tagdb.yaml").write_text(textwrap.dedent("""\
        version: 1
        plant: {name: traffic-bench}
        templates:
          robot:
            instances_from: {file: robots.yaml, initial: {xpos: start.x, ypos: start.y, xgoal: start.x, ygoal: start.y}}
            tags:
              xpos: {type: float64}
              ypos: {type: float64}
              heading: {type: float64}
              speed: {type: float64}
              navstate: {type: string}
              navreason: {type: string}
              route: {type: string}
              status: {type: bool}
              xgoal: {type: float64}
              ygoal: {type: float64}
              online: {type: bool}
        """))
    return [name for name, _, _ in starts]


class Simulated:
    """One vehicle: our vehicle's order logic on a point driving straight at SPEED."""

    def __init__(self, serial: str, node: str, x: float, y: float) -> None:
        self.logic = Vehicle("2.0")
        self.logic.map_id = "grid"
        self.logic.last_node_id = node
        self.pose = Pose(x, y)
        self.logic.pose = self.pose
        self.headers = Headers("2.0", "bench", serial)
        self.moving = False
        self.reported = -math.inf

    def step(self, now: float) -> None:
        target = self.logic.target(self.pose)
        self.moving = False
        if target is not None:
            dx, dy = target[0] - self.pose.x, target[1] - self.pose.y
            distance = math.hypot(dx, dy)
            travel = min(distance, SPEED * STEP)
            if travel > 1e-9:
                self.pose = Pose(self.pose.x + dx / distance * travel, self.pose.y + dy / distance * travel, math.atan2(dy, dx))
                self.moving = True
        self.logic.pose = self.pose
        self.logic.step(now, self.pose, self.moving)

    def state(self, now: float) -> bytes:
        body = self.logic.state(self.pose, SPEED if self.moving else 0.0, 0.0)
        return json.dumps({**self.headers.next("state", now), **body}).encode()


def occupied(vehicle: Simulated, roadmap) -> set[str]:
    """Where the vehicle is: the node it last passed, and unless it stands on that node, the edge after it and its end."""
    state = vehicle.logic
    found = {node_resource(state.last_node_id)} if state.last_node_id else set()
    last = roadmap.nodes.get(state.last_node_id)
    on_node = last is not None and math.hypot(vehicle.pose.x - last.x, vehicle.pose.y - last.y) < 0.01
    if not on_node and state.edges:
        start, end = state.edges[0][0].split("-")
        found |= {lane_resource(start, end), node_resource(end)}
    return found


async def run(args: argparse.Namespace) -> dict[str, float]:
    rng = random.Random(args.seed)
    directory = Path(tempfile.mkdtemp(prefix="vda5050-traffic-"))
    starts = write_plant(directory, args.vehicles, args.columns, args.rows, rng)
    config = load_config(directory / "tagdb.yaml")
    clock = SimClock()
    runtime = Runtime(config, clock, state_dir=directory / "state", retain=False)
    roadmap = load_roadmap(directory / "roadmap.yaml")
    settings = VdaSettings(roadmap=directory / "roadmap.yaml", lost_after=5.0, ack_timeout=1.0, lookahead=2, tick=STEP)
    robots = load_robots(directory / "robots.yaml")
    figures = {"conflicts": 0, "trips": 0, "invalid": 0, "messages": 0, "steps": 0}
    await runtime.start()
    try:
        db = runtime.db

        def arrivals(tags) -> None:
            figures["trips"] += sum(1 for tag in tags if tag.name.endswith("_navstate") and tag.value == "arrived")
        db.on_change(arrivals)
        links = {robot.id: VehicleLink(robot, "2.0", db) for robot in robots}
        control = MasterControl(roadmap, settings, links, db)
        vehicles = {}
        for robot, node in zip(robots, starts):
            point = roadmap.nodes[node]
            vehicles[robot.id] = Simulated(robot.vehicle.serial_number, node, point.x, point.y)
        names = list(roadmap.nodes)
        started = time.process_time()
        steps = int(args.minutes * 60 / STEP)
        for step in range(steps):
            now = clock.now()
            for robot_id, vehicle in vehicles.items():
                vehicle.step(now)
                # A vehicle's state on every event (a node passed, an order taken) and at least every second.
                if vehicle.logic.changed or now - vehicle.reported >= 1.0:
                    vehicle.logic.changed = False
                    vehicle.reported = now
                    control.on_state(links[robot_id], VehicleState.from_message(decode(vehicle.state(clock.wall()), "state", "2.0")), now)
            control.tick(now)
            for link, topic, body in control.outbox:
                message = {**link.headers.next(topic, clock.wall()), **body}
                kind = "order" if topic == "order" else "instantActions"
                figures["messages"] += 1
                if problems(kind, "2.0", message):
                    figures["invalid"] += 1
                payload = json.dumps(message).encode()
                if args.trace and link.id == args.trace:
                    print(f"  {now:.1f} -> {link.id} {topic} {body.get('orderId')}/{body.get('orderUpdateId')} "
                          f"{[(n['nodeId'], n['released']) for n in body.get('nodes', [])]}")
                target = vehicles[link.id].logic
                target.on_order(payload) if kind == "order" else target.on_instant_actions(payload)
            control.outbox.clear()
            seen: dict[str, str] = {}
            for robot_id, vehicle in vehicles.items():
                for resource in occupied(vehicle, roadmap):
                    if resource in seen:
                        figures["conflicts"] += 1
                        if figures["conflicts"] <= args.explain:
                            print(f"  conflict at {now:.1f} s: {resource} {seen[resource]} and {robot_id}")
                            for name in (seen[resource], robot_id):
                                trip, held = links[name].trip, sorted(control.traffic.held.get(name, ()))
                                logic = vehicles[name].logic
                                print(f"    {name}: trip {trip and (trip.route, trip.released, trip.passed)} holds {held}; vehicle at "
                                      f"{logic.last_node_id}, nodes {[w.node_id for w in logic.nodes]}, edges {logic.edges}, moving {vehicles[name].moving}")
                    seen[resource] = robot_id
            for robot_id, link in links.items():  # a free vehicle gets a new random goal, as a dispatcher would
                if link.trip is None and not db.value(f"{robot_id}_status") and rng.random() < 0.05:
                    if db.value(f"{robot_id}_navstate") in ("arrived", "idle", "failed", "") or link.states > 0:
                        goal = roadmap.nodes[rng.choice(names)]
                        db.submit([(f"{robot_id}_xgoal", goal.x), (f"{robot_id}_ygoal", goal.y), (f"{robot_id}_status", True)], "bench")
                        db.submit([(f"{robot_id}_navstate", "planning")], "bench")
            await clock.sleep(STEP)
            figures["steps"] += 1
        figures["cpu_s"] = time.process_time() - started
        figures["deadlocks_broken"] = control.deadlocks_broken
        figures["reservation_conflicts"] = control.traffic.conflicts
        figures["resends"] = sum(link.trip.resends for link in links.values() if link.trip is not None)
    finally:
        await runtime.stop()
        shutil.rmtree(directory, ignore_errors=True)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=50)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--columns", type=int, default=16)
    parser.add_argument("--rows", type=int, default=12)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--trace", default="", help="print every message to this vehicle")
    parser.add_argument("--explain", type=int, default=0, help="print the first N conflicts with both vehicles' trips and holdings")
    args = parser.parse_args()
    figures = asyncio.run(run(args))
    print(f"{args.vehicles} vehicles on a {args.columns} x {args.rows} grid roadmap ({SPACING:g} m lanes), "
          f"{args.minutes:g} simulated minutes in {figures['cpu_s']:.1f} CPU s")
    print(f"  trips completed {figures['trips']}, orders and instant actions {figures['messages']} "
          f"({figures['invalid']} off the schema), deadlocks broken {figures['deadlocks_broken']}")
    conflicts = figures["conflicts"] + figures["reservation_conflicts"]
    print(f"  two vehicles on one node or lane: {figures['conflicts']} times; reservation conflicts {figures['reservation_conflicts']}")
    verdict = "met" if conflicts == 0 and figures["invalid"] == 0 else "GOAL MISSED"
    print(f"0 reservation conflicts and 0 schema violations: {verdict}")


if __name__ == "__main__":
    main()
