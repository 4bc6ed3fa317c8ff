"""The fleet adapter: drives the plant's robots from `softplc run` (see `softplc.adapters.fleet`).

Simulated robots (`driver: sim`) each get a control loop in the runtime; remote robots
(`driver: remote`) run the same driver in a `softplc robot-agent` process, and this adapter
publishes their reports to their tags and marks those tags BAD while the agent is away
(`softplc.adapters.fleet.remote`). An agent that registers for a simulated robot is refused.
"""

from __future__ import annotations

import asyncio
import gc
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.adapters.fleet.remote import PUBLISHED_TAGS, AgentRefusal, RemoteLink
from softplc.adapters.fleet.settings import FleetSettings
from softplc.config import PlantConfig
from softplc.core.tagdb import Origin, TagDatabase
from softplc.core.tags import Quality, Tag
from softplc.robotics.controller import SpeedLimits
from softplc.robotics.driver import Command, DriverSettings, Report, RobotDriver
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import OccupancyGrid, load_map
from softplc.robotics.loop import ControlLoop, LoopStats, Sample, run_together
from softplc.robotics.peers import PEER_TAGS, PeerView
from softplc.robotics.planner import PathPlanner
from softplc.robotics.planning import ClockPlanning, Planning, ProcessPlanning
from softplc.robotics.robots import DriverKind, Pose, RobotFile, RobotSpec, load_robots
from softplc.util.plurals import plural
from softplc.util.tasks import cancel_and_wait

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

# Tags every robot needs (NAME → rNN_NAME); remote robots need REMOTE_TAGS too.
COMMAND_TAGS = ("xgoal", "ygoal", "status")
REMOTE_TAGS = ("report", "agent", "online")
REQUIRED_TAGS = tuple(dict.fromkeys((*COMMAND_TAGS, *PUBLISHED_TAGS, *PEER_TAGS)))
PHASES = 10  # robots' cycles are spread over this many slots of the cycle (smoother load)


class SharedPeers:
    """One PeerView shared by every in-process robot, kept up to date from tag changes."""

    def __init__(self, db: TagDatabase, ids: Sequence[str]) -> None:
        self._slots = {f"{robot_id}_{tag}": (index, tag) for index, robot_id in enumerate(ids) for tag in PEER_TAGS}
        self._view = PeerView.from_tags(list(ids), db.value)
        self.unsubscribe = db.on_change(self._changed)

    def _changed(self, tags: Sequence[Tag]) -> None:
        slots, view = self._slots, self._view
        for tag in tags:
            slot = slots.get(tag.name)
            if slot is not None:
                value = tag.value
                if tag.quality is not Quality.GOOD and slot[1] in ("navstate", "speed"):
                    value = "offline" if slot[1] == "navstate" else 0.0  # an absent robot stands where it was
                view.update(slot[0], slot[1], value)

    def get(self) -> PeerView:
        return self._view


class TagIO:
    """A simulated robot's inputs and outputs: its tags in the runtime's database."""

    def __init__(self, db: TagDatabase, robot_id: str, peers: SharedPeers) -> None:
        self.db = db
        self.id = robot_id
        self._peers = peers
        self._goal_x, self._goal_y, self._status = (self.db[f"{robot_id}_{name}"] for name in COMMAND_TAGS)
        self._names = {name: f"{robot_id}_{name}" for name in (*PUBLISHED_TAGS, "status")}
        self._last: dict[str, Any] = {}
        self.source = Origin(f"fleet:{robot_id}", role=None)
        self.driver: RobotDriver | None = None  # set once made: a standby keeps it on the active's pose

    def command(self) -> Command:
        # The standby of a redundant pair (docs/redundancy.md) drives nothing: its simulated robot
        # stands where the active's is (the mirrored tags), so a takeover carries on from there.
        role = self.db.role
        if role is not None and not role.is_active() and self.driver is not None:
            db = self.db
            self.driver.pose = Pose(float(db.value(self._names["xpos"])), float(db.value(self._names["ypos"])),
                                    float(db.value(self._names["heading"])))
        return Command(self._goal_x.value, self._goal_y.value, bool(self._status.value))

    def peers(self) -> PeerView:
        return self._peers.get()

    async def publish(self, report: Report) -> None:
        names = self._names
        values = {
            "xpos": report.x, "ypos": report.y, "heading": report.heading, "speed": report.speed,
            "navstate": report.navstate.value, "navreason": report.reason, "route": report.route,
        }
        # Only what changed: a parked robot costs nothing, a moving one ~5 writes a cycle.
        items = [(names[key], value) for key, value in values.items() if self._last.get(key) != value]
        self._last.update(values)
        if report.status is not None:
            items.append((names["status"], report.status))
        role = self.db.role
        if items and (role is None or role.is_active()):  # a standby's writes would be refused: it mirrors the active's
            for rejected in self.db.submit(items, self.source):
                if rejected is not None:
                    log.warning("robot %s: %s", self.id, rejected)


class FleetAdapter:
    """Drives every robot of a robots file on a map; see the `softplc.adapters.fleet` docstring."""

    name = "fleet"

    def __init__(
        self,
        robots: RobotFile,
        grid: OccupancyGrid | Floor,
        *,
        cycle: float = 0.1,
        max_linear_speed: float = 0.2,
        max_angular_speed: float = 0.4,
        planning_resolution: float = 0.1,
        heartbeat_timeout: float = 3.0,
        record: bool = False,
        settings: DriverSettings | None = None,
    ) -> None:
        self.robots = robots
        self.floor = grid if isinstance(grid, Floor) else Floor(grid, planning_resolution=planning_resolution)
        self.cycle = cycle
        self.max_linear_speed = max_linear_speed
        self.max_angular_speed = max_angular_speed
        self.heartbeat_timeout = heartbeat_timeout
        self.driver_settings = settings or DriverSettings()
        self.record = record
        self.drivers: dict[str, RobotDriver] = {}
        self.loops: dict[str, ControlLoop] = {}
        self.remotes: dict[str, RemoteLink] = {}
        self.trajectories: dict[str, list[Sample]] = {}
        self._plant: Plant | None = None
        self._tasks: list[asyncio.Task[Any]] = []
        self._unsubscribe: Any = None
        self._cleanup: list[Any] = []
        self.refusals: dict[str, AgentRefusal] = {}
        self._watch: dict[str, tuple[RemoteLink | AgentRefusal, str]] = {}
        self._planning: ProcessPlanning | None = None

    @classmethod
    def from_config(cls, config: PlantConfig, *, record: bool = False, **overrides: Any) -> FleetAdapter:
        """The adapter for a plant's `fleet:` section (raises ConfigError for bad files)."""
        settings = FleetSettings.from_config(config)
        return cls.from_files(
            settings.robots, settings.map, cycle=settings.cycle, max_linear_speed=settings.max_linear_speed,
            max_angular_speed=settings.max_angular_speed, planning_resolution=settings.planning_resolution,
            heartbeat_timeout=settings.heartbeat_timeout, record=record,
            **overrides,
        )

    @classmethod
    def from_files(cls, robots: str | Path, map_yaml: str | Path, **options: Any) -> FleetAdapter:
        """The adapter for a robots file and a map YAML."""
        return cls(load_robots(robots), load_map(map_yaml), **options)

    # -- adapter protocol ----------------------------------------------------------------

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        self._plant = plant
        db = plant.tags
        missing = [f"{robot.id}_{name}" for robot in self.robots for name in self._needed(robot) if f"{robot.id}_{name}" not in db]
        if missing:
            shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
            raise AdapterError(f"fleet: the robots of {self.robots.path} need tags that tagdb.yaml does not declare: {shown} "
                               "(add them to the robot template; see docs/robots.md)")
        for robot in self.robots:
            if not self.floor.fits(robot.start.x, robot.start.y, robot.radius):
                raise AdapterError(f"fleet: {self.robots.location(robot.id, 'start')}: robot {robot.id} starts at "
                                   f"({robot.start.x:g}, {robot.start.y:g}), which is not free floor for its size on the map")
        ids = self.robots.ids
        planners: list[PathPlanner] = []  # one per robot size, the map inflated now, not mid-run
        for robot in self.robots:
            if robot.driver is DriverKind.VDA5050:
                continue  # driven by the VDA 5050 master control (softplc/adapters/vda5050), on its own computer
            planner = self.floor.planner(robot.radius)
            if planner not in planners:
                planners.append(planner)
        db.submit([(f"{robot.id}_radius", robot.radius) for robot in self.robots], Origin("fleet", role=None))
        peers = SharedPeers(db, ids)
        self._cleanup.append(peers.unsubscribe)
        limits = {robot.id: self.limits(robot) for robot in self.robots}
        sim = [robot for robot in self.robots if robot.driver is DriverKind.SIM]
        planning: Planning = ClockPlanning(plant.clock)
        if sim and not plant.clock.simulated:
            self._planning = ProcessPlanning(planners, planning)
            await self._planning.start()
            planning = self._planning
        slots: dict[int, list[ControlLoop]] = {}
        for index, robot in enumerate(sim):
            pose = Pose(float(db.value(f"{robot.id}_xpos")), float(db.value(f"{robot.id}_ypos")), float(db.value(f"{robot.id}_heading")))
            driver = RobotDriver(robot, self.floor, limits[robot.id], self.driver_settings, cycle=self.cycle, pose=pose)
            record = self.trajectories.setdefault(robot.id, []) if self.record else None
            io = TagIO(db, robot.id, peers)
            io.driver = driver
            slot = index % PHASES
            loop = ControlLoop(driver, io, plant.clock, self.cycle, phase=slot * self.cycle / PHASES, record=record, planning=planning)
            self.drivers[robot.id] = driver
            self.loops[robot.id] = loop
            slots.setdefault(slot, []).append(loop)
        for slot, loops in sorted(slots.items()):
            # The robots of one slot step one after the other in one task (in the order of the robots file).
            name = f"robot-{loops[0].driver.spec.id}" if len(loops) == 1 else f"robots-phase-{slot}"
            self._tasks.append(plant.spawn(run_together(loops, plant.clock, self.cycle, loops[0].phase), name))
        for robot in self.robots:
            if robot.driver is DriverKind.REMOTE:
                link = RemoteLink(db, robot, plant.clock.now, self.heartbeat_timeout)
                link.go_offline("not connected yet")
                self.remotes[robot.id] = link
                self._watch[f"{robot.id}_report"] = (link, "report")
                self._watch[f"{robot.id}_agent"] = (link, "agent")
            elif robot.driver is DriverKind.SIM and f"{robot.id}_agent" in db:  # an agent may try to register for it: refuse it
                refusal = AgentRefusal(db, robot, self.robots.path, plant.clock.now)
                self.refusals[robot.id] = refusal
                self._watch[f"{robot.id}_agent"] = (refusal, "agent")
        if self._watch:
            self._unsubscribe = db.on_change(self._on_change)
        if self.remotes:
            self._tasks.append(plant.spawn(self._heartbeats(), "fleet-heartbeats"))
        # The maps, planners and robots live as long as the runtime: keep them out of the
        # garbage collector's full passes (a full pass over them stalled the loop for >100 ms).
        gc.freeze()

    async def stop(self) -> None:
        await cancel_and_wait(self._tasks)
        self._tasks.clear()
        if self._planning is not None:
            await self._planning.stop()
            self._planning = None
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        for unsubscribe in self._cleanup:
            unsubscribe()
        self._cleanup.clear()

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py): robots by navigation state (offline: no good value)."""
        if self._plant is None:
            return {}
        db = self._plant.tags
        states: dict[str, int] = {}
        for robot in self.robots:
            tag = db.get(f"{robot.id}_navstate")
            state = "offline" if tag is None or tag.quality is not Quality.GOOD else str(tag.value)
            states[state] = states.get(state, 0) + 1
        return {"robots": states}

    def describe(self) -> str:
        remote = len([r for r in self.robots if r.driver is DriverKind.REMOTE])
        vehicles = len([r for r in self.robots if r.driver is DriverKind.VDA5050])
        width, height = self.floor.grid.size_m
        simulated = len(self.robots) - remote - vehicles
        shown = f"{simulated} simulated, {remote} remote" + (f", {vehicles} VDA 5050 (softplc/adapters/vda5050)" if vehicles else "")
        return (f"fleet: {plural(len(self.robots), 'robot')} ({shown}) "
                f"on map '{self.floor.grid.name}' {width:.2f} x {height:.2f} m, cycle {self.cycle * 1000:g} ms")

    # -- for programs, scenarios and tests -----------------------------------------------

    def limits(self, robot: RobotSpec) -> SpeedLimits:
        """The robot's own limits, capped by the floor's."""
        return SpeedLimits(min(robot.max_linear_speed, self.max_linear_speed), min(robot.max_angular_speed, self.max_angular_speed))

    def pose(self, robot_id: str) -> Pose:
        """Where a robot is now (a remote robot: as last reported)."""
        if robot_id in self.drivers:
            return self.drivers[robot_id].pose
        assert self._plant is not None
        value = self._plant.tags.value
        return Pose(float(value(f"{robot_id}_xpos")), float(value(f"{robot_id}_ypos")), float(value(f"{robot_id}_heading")))

    def trajectory(self, robot_id: str) -> list[Sample]:
        """Every cycle of a simulated robot (only with `record=True`)."""
        return self.trajectories.get(robot_id, [])

    def stats(self) -> dict[str, LoopStats]:
        return {robot_id: loop.stats for robot_id, loop in self.loops.items()}

    # -- remote robots -------------------------------------------------------------------

    def _needed(self, robot: RobotSpec) -> tuple[str, ...]:
        return (*REQUIRED_TAGS, *REMOTE_TAGS) if robot.driver is DriverKind.REMOTE else REQUIRED_TAGS

    def _on_change(self, tags: Sequence[Tag]) -> None:
        watch = self._watch
        for tag in tags:
            entry = watch.get(tag.name)
            if entry is None:
                continue
            link, kind = entry
            if kind == "report" and isinstance(link, RemoteLink):
                link.on_report(str(tag.value))
            elif kind == "agent":
                link.on_agent(str(tag.value))

    async def _heartbeats(self) -> None:
        assert self._plant is not None
        clock = self._plant.clock
        period = min(0.5, self.heartbeat_timeout / 4)
        while True:
            await clock.sleep(period)
            for link in self.remotes.values():
                link.check()
