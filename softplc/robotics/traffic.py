"""Traffic rules between robots: when to stop, slow down or make way, and what to plan around.

The rules are deterministic and need only the other robots' tags (their `PeerView`):

- a robot never makes a move that brings it closer than `safety` to another robot's footprint
  within the look-ahead horizon (other robots are extrapolated along their heading);
- toward a parked robot (idle, arrived, failed) or one whose id sorts first (right of way), it
  stops; toward a robot it has right of way over, it slows down and stops only when close;
- a robot without right of way that stays blocked plans a detour that keeps out of the other
  robot's route (`rNN_route`), or, if there is none, moves to the nearest spot off that route
  and waits there until the way is clear — so two robots never deadlock in an aisle;
- a stopped robot that a robot with right of way is waiting for (its `rNN_navreason` names it)
  makes way at once, farther from that robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from softplc.robotics.controller import integrate
from softplc.robotics.peers import Peer, PeerView
from softplc.robotics.planner import Corridor, Disc
from softplc.robotics.robots import Pose


@dataclass(frozen=True)
class TrafficSettings:
    horizon: float = 1.5  # s of motion checked against other robots
    safety: float = 0.12  # m kept between footprints
    hysteresis: float = 0.08  # m more asked of the robot we stopped for, before moving again
    plan_clearance: float = 0.3  # m a detour keeps from another robot's footprint (> safety + hysteresis)
    sense_range: float = 3.0  # m within which other robots are considered
    slow_band: float = 0.6  # m over which it slows for a robot it has right of way over
    route_horizon: float = 6.0  # m of another robot's route a detour keeps out of
    room: float = 0.4  # m more kept from a robot that is waiting for us


@dataclass
class Verdict:
    """The speed the other robots allow this cycle, and who limits it."""

    v: float
    blocker: Peer | None = None
    yielding: bool = False  # stopped for a navigating robot with right of way


class Traffic:
    """The traffic rules as seen by one robot."""

    def __init__(self, robot_id: str, radius: float, settings: TrafficSettings = TrafficSettings()) -> None:
        self.id = robot_id
        self.radius = radius
        self.settings = settings

    def check(self, pose: Pose, v: float, w: float, peers: PeerView, previous: str | None = None) -> Verdict:
        """Limit the linear speed `v` (turning in place is always safe for round robots)."""
        settings = self.settings
        my_rank = peers.rank_of(self.id)
        verdict = Verdict(v)
        for peer in peers.near(self.id, pose.x, pose.y, settings.sense_range):
            limit = self.radius + peer.radius + settings.safety
            if peer.id == previous:
                limit += settings.hysteresis
            gap = math.hypot(peer.x - pose.x, peer.y - pose.y)
            if gap - (abs(verdict.v) + (peer.speed if peer.active else 0.0)) * settings.horizon >= limit:
                continue  # too far to meet within the horizon, whatever either does
            stay = self.min_distance(pose, peer, 0.0, 0.0)
            go = self.min_distance(pose, peer, verdict.v, w) if verdict.v else stay
            if not (go < limit and go < stay - 1e-4):
                continue  # our motion does not bring us closer than staying put would
            has_way = peer.active and peer.rank < my_rank
            if not peer.active or has_way:
                verdict.v = 0.0
                if verdict.blocker is None or (has_way and not verdict.yielding):
                    verdict.blocker, verdict.yielding = peer, has_way
            else:
                verdict.v *= max(0.0, min(1.0, (gap - limit) / settings.slow_band))
                if verdict.v < 0.01:
                    verdict.v = 0.0
                    verdict.blocker = verdict.blocker or peer
        return verdict

    def min_distance(self, pose: Pose, peer: Peer, v: float, w: float) -> float:
        """Smallest distance to `peer` over the horizon if we drive at (v, w) and it keeps going."""
        speed = peer.speed if peer.active else 0.0
        cos_h, sin_h = math.cos(peer.heading), math.sin(peer.heading)
        best = math.hypot(peer.x - pose.x, peer.y - pose.y)
        steps = 6
        for k in range(1, steps + 1):
            t = self.settings.horizon * k / steps
            mine = integrate(pose, v, w, t) if v else pose
            best = min(best, math.hypot(peer.x + speed * t * cos_h - mine.x, peer.y + speed * t * sin_h - mine.y))
        return best

    def disc(self, pose: Pose, peer: Peer, resolution: float) -> Disc:
        """A peer as a hard obstacle for planning (never covering our own position)."""
        radius = self.radius + peer.radius + self.settings.plan_clearance
        gap = math.hypot(peer.x - pose.x, peer.y - pose.y)
        return Disc(peer.x, peer.y, max(0.0, min(radius, gap - 1.5 * resolution)))

    def parked(self, pose: Pose, goal: tuple[float, float], peers: PeerView, resolution: float) -> list[Disc]:
        """Parked robots near the way to `goal`, as obstacles for a new trip.

        Only those within reach of the straight line's midpoint count: a path rarely strays
        farther, and one that does meets them with the local traffic check instead.
        """
        mid_x, mid_y = (pose.x + goal[0]) / 2, (pose.y + goal[1]) / 2
        reach = math.hypot(goal[0] - pose.x, goal[1] - pose.y) / 2 + self.settings.sense_range
        return [self.disc(pose, peer, resolution) for peer in peers.near(self.id, mid_x, mid_y, reach) if not peer.active]

    def demanding(self, pose: Pose, peers: PeerView) -> Peer | None:
        """A navigating robot with right of way that says it is waiting for us (in its navreason)."""
        my_rank = peers.rank_of(self.id)
        suffix = f" {self.id}"
        for peer in peers.near(self.id, pose.x, pose.y, self.settings.sense_range):
            if peer.active and peer.rank < my_rank and peer.reason.endswith(suffix):
                return peer
        return None

    def detour(self, pose: Pose, peers: PeerView, resolution: float, *, make_way: bool) -> tuple[list[Disc], list[Corridor]]:
        """Obstacles for a detour: nearby robots, and (to make way) the routes of those with right of way."""
        settings = self.settings
        my_rank = peers.rank_of(self.id)
        discs: list[Disc] = []
        keep_out: list[Corridor] = []
        for peer in peers.near(self.id, pose.x, pose.y, settings.sense_range + 2.0):
            discs.append(self.disc(pose, peer, resolution))
            if make_way and peer.active and peer.rank < my_rank:
                reach = self.radius + peer.radius + settings.plan_clearance
                if peer.reason.endswith(f" {self.id}"):
                    reach += settings.room  # it is waiting for us: clear its way by a margin
                travelled = 0.0
                route = peer.remaining_route()
                for a, b in zip(route, route[1:]):
                    keep_out.append(Corridor(a[0], a[1], b[0], b[1], reach))
                    travelled += math.dist(a, b)
                    if travelled > settings.route_horizon:
                        break
        return discs, keep_out
