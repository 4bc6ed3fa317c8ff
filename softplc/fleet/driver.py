"""A robot's local navigation: goal in, pose and navigation state out, once per control cycle.

`RobotDriver.step()` is one cycle of the thesis's local control program (§4.5.3): it takes the
goal tags and what the robot knows of the others (a `PeerView` built from their tags), follows
its planned path with pure pursuit, and returns what to publish. It never plans inline: when it
needs a path it sets a request that the caller runs off the event loop (`run_plan`) and hands
back with `plan_done()`. The same class drives simulated robots in the runtime and real or
simulated robots in a remote agent.

Traffic rule (deterministic, no deadlock between two robots): a robot stops for any robot it
would hit; it yields to a navigating robot whose id sorts first, and after `yield_wait` plans a
detour around it; it only slows down for a robot it has right of way over, and detours around
it only after `patience`. Parked robots (idle, arrived, failed) are static obstacles.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from softplc.fleet.controller import PurePursuit, SpeedLimits, integrate
from softplc.fleet.floor import Floor
from softplc.fleet.peers import Peer, PeerView
from softplc.fleet.planner import Corridor, Disc, PathPlanner, Plan
from softplc.fleet.robots import Pose, RobotSpec


class NavState(enum.Enum):
    """Navigation state published in `rNN_navstate` (the reason goes to `rNN_navreason`)."""

    IDLE = "idle"
    PLANNING = "planning"
    MOVING = "moving"
    BLOCKED = "blocked"
    ARRIVED = "arrived"
    FAILED = "failed"


@dataclass(frozen=True)
class DriverSettings:
    """Tuning of the local navigation (defaults suit the thesis TurtleBots at 0.2 m/s)."""

    goal_tolerance: float = 0.5  # goal reached: status cleared (thesis Eq. 4.1)
    stop_tolerance: float = 0.1  # then keeps creeping to within this of the goal
    horizon: float = 1.5  # s of motion checked against other robots
    safety: float = 0.12  # m kept between footprints
    plan_clearance: float = 0.2  # m a detour keeps from another robot's footprint
    sense_range: float = 3.0  # m within which other robots are considered
    slow_band: float = 0.6  # m over which it slows for a robot it has right of way over
    yield_wait: float = 1.0  # s stopped before detouring around a robot with right of way
    patience: float = 6.0  # s stopped before detouring around any other robot
    replan_interval: float = 2.0  # s between detour attempts while blocked
    give_up: float = 60.0  # s blocked before the goal fails
    corridor_length: float = 1.5  # m ahead of a navigating robot that detours avoid
    status_grace: float = 0.35  # s our own status write takes to show in the tags


@dataclass
class Command:
    """The goal tags as read this cycle."""

    goal_x: float
    goal_y: float
    status: bool


@dataclass
class Report:
    """What a cycle publishes. `status` is None unless the robot changed it this cycle."""

    x: float
    y: float
    heading: float
    speed: float
    turn_rate: float
    navstate: NavState
    reason: str
    status: bool | None = None
    status_seq: int = 0


@dataclass
class PlanRequest:
    """A plan the driver wants; run it with `run_plan` off the event loop."""

    serial: int
    planner: PathPlanner
    start: tuple[float, float]
    goal: tuple[float, float]
    discs: list[Disc] = field(default_factory=list)
    corridors: list[Corridor] = field(default_factory=list)
    detour: bool = False  # a re-plan around other robots (failure keeps the old path)


def run_plan(request: PlanRequest) -> Plan:
    """Plan around the other robots; if they block every way, plan through them (wait locally)."""
    plan = request.planner.plan(request.start, request.goal, request.discs, request.corridors)
    if not plan.ok and (request.discs or request.corridors) and not request.detour:
        plan = request.planner.plan(request.start, request.goal)
    return plan


class RobotDriver:
    """One robot's navigation state machine (see the module docstring)."""

    def __init__(
        self,
        spec: RobotSpec,
        floor: Floor,
        limits: SpeedLimits,
        settings: DriverSettings = DriverSettings(),
        *,
        cycle: float = 0.1,
        pose: Pose | None = None,
    ) -> None:
        self.spec = spec
        self.id = spec.id
        self.radius = spec.radius
        self.floor = floor
        self.planner = floor.planner(self.radius)
        self.limits = limits
        self.settings = settings
        self.cycle = cycle
        self.pursuit = PurePursuit()
        self.pose = pose or spec.start
        self.v = 0.0
        self.w = 0.0
        self.navstate = NavState.IDLE
        self.reason = ""
        self.goal: tuple[float, float] | None = None
        self.path: list[tuple[float, float]] | None = None
        self.segment = 0
        self.plans = 0  # plans requested so far (for tests and statistics)
        self.last_plan: Plan | None = None
        self._arrived = False
        self._request: PlanRequest | None = None
        self._pending: int | None = None  # serial of the plan in flight
        self._serial = 0
        self._blocked_since: float | None = None
        self._next_replan = 0.0
        self._status: bool | None = None  # last status we published
        self._status_until = -math.inf
        self._status_event: bool | None = None
        self.status_seq = 0

    # -- the cycle -----------------------------------------------------------------------

    def step(self, now: float, command: Command, peers: PeerView) -> Report:
        """One control cycle: react to the goal tags, follow the path, move, report."""
        self._status_event = None
        self._command(now, command, peers)
        v, w = 0.0, 0.0
        if self.path is not None:
            v, w = self._follow(now, peers)
        self.v, self.w = v, w
        if v or w:
            self.pose = integrate(self.pose, v, w, self.cycle)
        return Report(
            self.pose.x, self.pose.y, self.pose.heading, v, w, self.navstate, self.reason,
            self._status_event, self.status_seq,
        )

    def take_plan_request(self) -> PlanRequest | None:
        """The plan to run now, if any (the caller runs it and calls `plan_done`)."""
        request, self._request = self._request, None
        return request

    def plan_done(self, serial: int, plan: Plan, now: float) -> None:
        """Accept a finished plan (ignored if a newer goal superseded it)."""
        if serial != self._pending:
            return
        self._pending = None
        self.last_plan = plan
        if plan.ok:
            self.path = plan.path
            self.segment = 0
            if self.navstate is NavState.PLANNING:
                self._set_state(NavState.MOVING)
            return
        if self.navstate is NavState.PLANNING:
            self._fail(now, plan.reason)
        # A failed detour keeps the current path: the robot waits and tries again later.

    # -- commands ------------------------------------------------------------------------

    def _command(self, now: float, command: Command, peers: PeerView) -> None:
        goal = (command.goal_x, command.goal_y)
        status = command.status
        if self._status is not None and now < self._status_until:
            status = self._status  # our own write has not reached the tags yet
        if self.goal is None:
            self.goal = goal
            if self._distance(goal) > self.settings.goal_tolerance:
                self._start(now, goal, peers)
            return
        if math.dist(goal, self.goal) > 1e-6:
            self._start(now, goal, peers)
        elif status and self.navstate in (NavState.IDLE, NavState.ARRIVED, NavState.FAILED):
            self._start(now, goal, peers)  # asked again (e.g. after a failure): retry

    def _start(self, now: float, goal: tuple[float, float], peers: PeerView) -> None:
        self.goal = goal
        self.path = None
        self._arrived = False
        self._blocked_since = None
        self._pending = None
        if self._distance(goal) <= self.settings.goal_tolerance:
            self._arrive(now)
            return
        self._set_status(now, True)
        self._set_state(NavState.PLANNING)
        # Parked robots are obstacles from the start; moving ones are handled on the way.
        discs = [self._disc(peer) for peer in peers.near(self.id, self.pose.x, self.pose.y, 30.0) if not peer.active]
        self._request_plan(goal, discs, [], detour=False)

    def _request_plan(self, goal: tuple[float, float], discs: list[Disc], corridors: list[Corridor], *, detour: bool) -> None:
        self._serial += 1
        self.plans += 1
        self._pending = self._serial
        self._request = PlanRequest(self._serial, self.planner, (self.pose.x, self.pose.y), goal, discs, corridors, detour)

    def _arrive(self, now: float) -> None:
        self._arrived = True
        self._set_state(NavState.ARRIVED)
        self._set_status(now, False)

    def _fail(self, now: float, reason: str) -> None:
        self.path = None
        self._set_state(NavState.FAILED, reason)
        self._set_status(now, False)

    def _set_state(self, state: NavState, reason: str = "") -> None:
        self.navstate = state
        self.reason = reason

    def _set_status(self, now: float, value: bool) -> None:
        if self._status is value:
            return
        self._status = value
        self._status_until = now + self.settings.status_grace
        self._status_event = value
        self.status_seq += 1

    def _distance(self, point: tuple[float, float]) -> float:
        return math.hypot(point[0] - self.pose.x, point[1] - self.pose.y)

    # -- following -----------------------------------------------------------------------

    def _follow(self, now: float, peers: PeerView) -> tuple[float, float]:
        assert self.path is not None and self.goal is not None
        settings = self.settings
        pose = self.pose
        if not self._arrived and self._distance(self.goal) <= settings.goal_tolerance:
            self._arrive(now)
        end = self.path[-1]
        if math.hypot(end[0] - pose.x, end[1] - pose.y) <= settings.stop_tolerance:
            self.path = None
            if not self._arrived:  # a goal snapped out of an obstacle: as close as it gets
                self._arrive(now)
            return 0.0, 0.0
        self.segment = self.pursuit.progress(pose, self.path, self.segment)
        v, w = self.pursuit.command(pose, self.path, self.segment, self.limits, (self.v, self.w), self.cycle)
        v, blocker, yielding = self._traffic(v, w, peers)
        if v and not self._clear_of_walls(v, w):
            v, w = 0.0, 0.0
            self._blocked(now, None, "too close to a wall", settings.yield_wait, peers)
            return v, w
        if blocker is not None and v == 0.0:
            if self._arrived:  # the last centimetres are not worth a detour
                self.path = None
                return 0.0, 0.0
            what = "yielding to" if yielding else "blocked by" if not blocker.active else "waiting for"
            wait = settings.yield_wait if yielding or not blocker.active else settings.patience
            self._blocked(now, blocker, f"{what} {blocker.id}", wait, peers)
            return 0.0, w
        self._blocked_since = None
        if not self._arrived and self.navstate is not NavState.MOVING:
            self._set_state(NavState.MOVING)
        return v, w

    def _traffic(self, v: float, w: float, peers: PeerView) -> tuple[float, Peer | None, bool]:
        """The speed allowed by the other robots, the robot that limits it, and whether we yield."""
        settings = self.settings
        pose = self.pose
        my_rank = peers.rank_of(self.id)
        blocker: Peer | None = None
        yielding = False
        for peer in peers.near(self.id, pose.x, pose.y, settings.sense_range):
            limit = self.radius + peer.radius + settings.safety
            now_gap = math.hypot(peer.x - pose.x, peer.y - pose.y)
            stay = self._min_distance(peer, 0.0, 0.0)
            go = self._min_distance(peer, v, w) if v else stay
            if not (go < limit and go < stay - 1e-4):
                continue  # our motion does not bring us closer than staying put would
            if not peer.active or peer.rank < my_rank:
                v = 0.0
                if blocker is None or (peer.active and peer.rank < my_rank and not yielding):
                    blocker, yielding = peer, peer.active
            else:
                scale = max(0.0, min(1.0, (now_gap - limit) / settings.slow_band))
                v *= scale
                if v < 0.01:
                    v = 0.0
                    blocker = blocker or peer
        return v, blocker, yielding

    def _min_distance(self, peer: Peer, v: float, w: float) -> float:
        """Smallest distance to `peer` over the horizon if we drive at (v, w) and it keeps going."""
        pose = self.pose
        speed = peer.speed if peer.active else 0.0
        cos_h, sin_h = math.cos(peer.heading), math.sin(peer.heading)
        best = math.hypot(peer.x - pose.x, peer.y - pose.y)
        steps = 6
        for k in range(1, steps + 1):
            t = self.settings.horizon * k / steps
            mine = integrate(pose, v, w, t) if v else pose
            px, py = peer.x + speed * t * cos_h, peer.y + speed * t * sin_h
            best = min(best, math.hypot(px - mine.x, py - mine.y))
        return best

    def _clear_of_walls(self, v: float, w: float) -> bool:
        ahead = integrate(self.pose, v, w, self.cycle)
        if self.floor.fits(ahead.x, ahead.y, self.radius):
            return True
        # Already too close (e.g. pushed there by a detour): moving away is always allowed.
        return self.floor.clearance(ahead.x, ahead.y) > self.floor.clearance(self.pose.x, self.pose.y)

    def _blocked(self, now: float, blocker: Peer | None, reason: str, wait: float, peers: PeerView) -> None:
        settings = self.settings
        if self._blocked_since is None:
            self._blocked_since = now
            self._next_replan = now + wait
        if not self._arrived:
            self._set_state(NavState.BLOCKED, reason)
        if now - self._blocked_since >= settings.give_up:
            self._fail(now, f"{reason} for {settings.give_up:g} s")
            return
        if now >= self._next_replan and self._pending is None and self.goal is not None:
            self._next_replan = now + settings.replan_interval
            self._request_detour(peers)

    def _request_detour(self, peers: PeerView) -> None:
        settings = self.settings
        assert self.goal is not None
        discs, corridors = [], []
        for peer in peers.near(self.id, self.pose.x, self.pose.y, settings.sense_range + 2.0):
            discs.append(self._disc(peer))
            if peer.active:
                reach = self.radius + peer.radius + settings.plan_clearance
                x1 = peer.x + settings.corridor_length * math.cos(peer.heading)
                y1 = peer.y + settings.corridor_length * math.sin(peer.heading)
                corridors.append(Corridor(peer.x, peer.y, x1, y1, reach))
        self._request_plan(self.goal, discs, corridors, detour=True)

    def _disc(self, peer: Peer) -> Disc:
        radius = self.radius + peer.radius + self.settings.plan_clearance
        gap = math.hypot(peer.x - self.pose.x, peer.y - self.pose.y)
        # Never wall ourselves in: the disc stops short of where we stand.
        radius = min(radius, gap - 1.5 * self.planner.resolution)
        return Disc(peer.x, peer.y, max(radius, 0.0))
