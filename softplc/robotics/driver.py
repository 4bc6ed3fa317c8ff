"""A robot's local navigation: goal in, pose and navigation state out, once per control cycle.

`RobotDriver.step()` is one cycle of the thesis's local control program (§4.5.3): it takes the
goal tags and what the robot knows of the others (a `PeerView` built from their tags), follows
its planned path with pure pursuit, and returns what to publish. It never plans inline: when it
needs a path it sets a request that the caller runs off the event loop (`run_plan`) and hands
back with `plan_done()`. The same class drives simulated robots in the runtime and real or
simulated robots in a remote agent.

Traffic between robots follows `softplc.robotics.traffic`: stop for parked robots and for robots
with right of way (id sorts first), slow down for the others; a robot that stays blocked plans
a detour — after `yield_wait` when it has to make way (moving off the other's route if need be),
after `patience` when it has right of way. Blocked for `give_up` seconds, the trip fails.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from softplc.robotics.arrival import within_goal
from softplc.robotics.controller import PurePursuit, SpeedLimits, integrate
from softplc.robotics.floor import Floor
from softplc.robotics.peers import Peer, PeerView, encode_route
from softplc.robotics.planner import Corridor, Disc, PathPlanner, Plan
from softplc.robotics.robots import Pose, RobotSpec
from softplc.robotics.traffic import Traffic, TrafficSettings


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

    # Arrival (status cleared) is softplc.robotics.arrival's rule, shared with the sequencers: not a setting.
    stop_tolerance: float = 0.1  # after arriving, keeps creeping to within this of the goal
    yield_wait: float = 1.0  # s stopped before making way for a robot with right of way
    patience: float = 6.0  # s stopped before detouring around a robot we have right of way over
    replan_interval: float = 2.0  # s between detour attempts while blocked
    free_hold: float = 1.0  # s of free driving that end a blockage (no flapping)
    make_way_limit: float = 20.0  # s of making way after which going round is tried too
    give_up: float = 180.0  # s blocked before the trip fails
    status_grace: float = 0.35  # s our own status write takes to show in the tags
    traffic: TrafficSettings = TrafficSettings()


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
    route: str = ""


@dataclass
class PlanRequest:
    """A plan the driver wants; run it with `run_plan` off the event loop."""

    serial: int
    planner: PathPlanner
    start: tuple[float, float]
    goal: tuple[float, float]
    discs: list[Disc] = field(default_factory=list)
    keep_out: list[Corridor] = field(default_factory=list)
    detour: bool = False  # a re-plan while blocked (failure keeps the robot waiting)
    make_way: bool = False  # if no detour exists, find a refuge off the keep-out routes


def run_plan(request: PlanRequest) -> Plan:
    """Run a request: a trip plan, a detour, or a refuge to make way (see PlanRequest)."""
    planner = request.planner
    plan = planner.plan(request.start, request.goal, request.discs, (), request.keep_out)
    if plan.ok or not request.detour and not request.discs:
        return plan
    if not request.detour:
        # Parked robots block every way (e.g. one stands on the goal): drive and wait there.
        return planner.plan(request.start, request.goal)
    if request.make_way:
        refuge = planner.refuge(request.start, request.discs, request.keep_out)
        refuge.refuge = True
        return refuge
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
        self.traffic = Traffic(spec.id, self.radius, settings.traffic)
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
        self.route = ""  # the path being followed, as published in rNN_route
        self.plans = 0  # plans requested so far (for tests and statistics)
        self.last_plan: Plan | None = None
        self._arrived = False
        self._refuge = False  # the path leads off another robot's route, not to the goal
        self._waiting = False  # no path, still on a trip: waiting for the way to clear
        self._request: PlanRequest | None = None
        self._pending: int | None = None  # serial of the plan in flight
        self._serial = 0
        self._blocked_since: float | None = None
        self._free_since: float | None = None
        self._blocker: str | None = None
        self._blocked_reason = ""
        self._make_way = False
        self._next_replan = 0.0
        self._status: bool | None = None  # last status we published
        self._observed = False  # status as read from the tags this cycle
        self._status_until = -math.inf
        self._status_event: bool | None = None
        self.status_seq = 0

    # -- the cycle -----------------------------------------------------------------------

    def step(self, now: float, command: Command, peers: PeerView) -> Report:
        """One control cycle: react to the goal tags, follow the path, move, report."""
        self._command(now, command, peers)
        v, w = 0.0, 0.0
        if self.path is not None:
            v, w = self._follow(now, peers)
        elif self._waiting:
            self._blocked(now, self._blocked_reason, self.settings.replan_interval, peers, self._make_way)
        self.v, self.w = v, w
        if v or w:
            self.pose = integrate(self.pose, v, w, self.cycle)
        event, self._status_event = self._status_event, None  # also events of plan_done()
        return Report(self.pose.x, self.pose.y, self.pose.heading, v, w, self.navstate, self.reason, event, self.status_seq, self.route)

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
            self._set_path(plan.path, refuge=plan.refuge)
            if self.navstate is NavState.PLANNING:
                self._set_state(NavState.MOVING)
            return
        if self.navstate is NavState.PLANNING:
            self._fail(now, plan.reason)
        # A failed detour keeps the robot where it is: it waits and tries again later.

    # -- commands ------------------------------------------------------------------------

    def _command(self, now: float, command: Command, peers: PeerView) -> None:
        goal = (command.goal_x, command.goal_y)
        status = self._observed = command.status
        if self._status is not None and now < self._status_until:
            status = self._status  # our own write has not reached the tags yet
        if self.goal is None:
            self.goal = goal
            if not self._within(goal):
                self._start(now, goal, peers)
            return
        if math.dist(goal, self.goal) > 1e-6:
            self._start(now, goal, peers)
        elif status and self.navstate in (NavState.IDLE, NavState.ARRIVED, NavState.FAILED):
            self._start(now, goal, peers)  # asked again (e.g. after a failure): retry

    def _start(self, now: float, goal: tuple[float, float], peers: PeerView) -> None:
        self.goal = goal
        self._set_path(None)
        self._waiting = False
        self._arrived = False
        self._blocked_since = None
        self._blocker = None
        self._make_way = False
        self._pending = None
        if self._within(goal):
            self._arrive(now)
            return
        self._set_status(now, True)
        self._set_state(NavState.PLANNING)
        # Parked robots are obstacles from the start; moving ones are handled on the way.
        discs = self.traffic.parked(self.pose, goal, peers, self.planner.resolution)
        self._request_plan(PlanRequest(0, self.planner, (self.pose.x, self.pose.y), goal, discs))

    def _request_plan(self, request: PlanRequest) -> None:
        self._serial += 1
        self.plans += 1
        self._pending = request.serial = self._serial
        self._request = request

    def _set_path(self, path: list[tuple[float, float]] | None, *, refuge: bool = False) -> None:
        self.path = path
        self.segment = 0
        self._refuge = refuge and path is not None
        if path is not None:
            self._waiting = False
        self.route = encode_route(path) if path is not None else ""

    def _arrive(self, now: float) -> None:
        self._arrived = True
        self._set_state(NavState.ARRIVED)
        self._set_status(now, False)

    def _fail(self, now: float, reason: str) -> None:
        self._set_path(None)
        self._waiting = False
        self._set_state(NavState.FAILED, reason)
        self._set_status(now, False)

    def _set_state(self, state: NavState, reason: str = "") -> None:
        self.navstate = state
        self.reason = reason

    def _set_status(self, now: float, value: bool) -> None:
        if self._status is value and self._observed is value:
            return
        self._status = value
        self._status_until = now + self.settings.status_grace
        self._status_event = value
        self.status_seq += 1

    def _occupies_goal(self, peer: Peer) -> bool:
        return self.goal is not None and within_goal(peer.x, peer.y, self.goal[0], self.goal[1])

    def _within(self, goal: tuple[float, float]) -> bool:
        return within_goal(self.pose.x, self.pose.y, goal[0], goal[1])

    # -- following -----------------------------------------------------------------------

    def _follow(self, now: float, peers: PeerView) -> tuple[float, float]:
        assert self.path is not None and self.goal is not None
        settings = self.settings
        pose = self.pose
        if not self._arrived and self._within(self.goal):
            self._arrive(now)
        end = self.path[-1]
        if math.hypot(end[0] - pose.x, end[1] - pose.y) <= settings.stop_tolerance:
            refuge = self._refuge
            self._set_path(None)
            if refuge:  # off the other robot's route: wait there until the way is clear
                self._waiting = True
            elif not self._arrived:  # a goal snapped out of an obstacle: as close as it gets
                self._arrive(now)
            return 0.0, 0.0
        careful = not self.planner.is_free(pose.x, pose.y)  # inside the safety margin of a wall
        self.segment = self.pursuit.progress(pose, self.path, self.segment) if not careful else self.segment
        v, w = self.pursuit.command(pose, self.path, self.segment, self.limits, (self.v, self.w), self.cycle, careful=careful)
        verdict = self.traffic.check(pose, v, w, peers, self._blocker)
        v = verdict.v
        if v and not self._clear_of_walls(v, w):
            self._blocker = None
            self._blocked(now, "too close to a wall", settings.yield_wait, peers, False)
            return 0.0, 0.0
        blocker = verdict.blocker
        if blocker is not None and v == 0.0:
            self._blocker = blocker.id
            if self._arrived:  # the last centimetres are not worth a detour
                self._set_path(None)
                return 0.0, 0.0
            if verdict.yielding:
                self._blocked(now, f"yielding to {blocker.id}", settings.yield_wait, peers, True)
            elif not blocker.active and self._occupies_goal(blocker):
                # Its station is taken: wait here until the robot there leaves (or give up).
                self._blocked(now, f"waiting for the station, {blocker.id} is there", settings.yield_wait, peers, False)
            elif not blocker.active:
                self._blocked(now, f"blocked by {blocker.id}", settings.yield_wait, peers, False)
            else:
                self._blocked(now, f"waiting for {blocker.id}", settings.patience, peers, False)
            return 0.0, w
        self._blocker = None
        if self._free_since is None:
            self._free_since = now
        if now - self._free_since >= settings.free_hold and not self._refuge:
            self._blocked_since = None
        if not self._arrived:
            if self._refuge:
                self._set_state(NavState.BLOCKED, self._blocked_reason)
            elif self.navstate is not NavState.MOVING:
                self._set_state(NavState.MOVING)
        return v, w

    def _clear_of_walls(self, v: float, w: float) -> bool:
        ahead = integrate(self.pose, v, w, self.cycle)
        if self.floor.fits(ahead.x, ahead.y, self.radius):
            return True
        # Already too close (e.g. pushed there by a detour): moving no closer is allowed.
        return self.floor.clearance(ahead.x, ahead.y) >= self.floor.clearance(self.pose.x, self.pose.y)

    def _blocked(self, now: float, reason: str, wait: float, peers: PeerView, make_way: bool) -> None:
        settings = self.settings
        self._free_since = None
        if self._blocked_since is None:
            self._blocked_since = now
            self._next_replan = now + wait
        demand = self.traffic.demanding(self.pose, peers)
        if demand is not None and not make_way:
            # A robot with right of way waits for us: get out of its way, now.
            make_way, reason = True, f"yielding to {demand.id}"
            if not self._make_way:
                self._next_replan = min(self._next_replan, now)
        if make_way and reason.startswith("yielding"):
            reason = "making way for" + reason[len("yielding to"):]
        self._blocked_reason = reason
        self._make_way = make_way or self._make_way and self._refuge
        if not self._arrived:
            self._set_state(NavState.BLOCKED, reason)
        if now - self._blocked_since >= settings.give_up:
            self._fail(now, f"{reason} for {settings.give_up:g} s")
            return
        if now >= self._next_replan and self._pending is None and self.goal is not None:
            self._next_replan = now + settings.replan_interval
            if make_way and now - self._blocked_since >= settings.make_way_limit and int(now / settings.replan_interval) % 2:
                make_way = False  # making way leads nowhere: every other attempt, try going round instead
            discs, keep_out = self.traffic.detour(self.pose, peers, self.planner.resolution, make_way=make_way)
            start = (self.pose.x, self.pose.y)
            self._request_plan(PlanRequest(0, self.planner, start, self.goal, discs, keep_out, detour=True, make_way=make_way))
