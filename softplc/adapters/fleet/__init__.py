"""Heterogeneous robot fleet: configuration, compatibility, maps, planning and robot drivers.

Configuration (`robots/`, docs/robots.md):
    robots = load_robots("robots/robots.yaml")      # RobotFile of RobotSpec (id, size, speeds, hardware, start, driver)
    tasks = load_tasks("robots/tasks.yaml")         # TaskFile of TaskSpec (requirements, source/destination)
    grid = load_map("robots/maps/factory.yaml")     # OccupancyGrid (ROS map_server YAML + PGM)

Compatibility (thesis §4.7.2, SPEC §3), usable from programs:
    compatible(robot, task) -> bool; compatible_tasks(robot, tasks); compatible_robots(task, robots)
    compatibility_matrix(robots, tasks) -> {robot_id: {task_id: bool}}
    Compatibility.load(robots_file, tasks_file).check("r01", "t02")

Driving robots in a runtime (what `softplc run` does when tagdb.yaml has a `fleet:` section):
    fleet = FleetAdapter.from_config(config, record=True)      # or FleetAdapter(robots, grid, cycle=0.1, ...)
    # or: FleetAdapter.from_files("robots/robots.yaml", "robots/maps/factory.yaml", record=True)
    runtime.add_adapter(fleet)                                   # before runtime.start()
    fleet.pose("r01") -> Pose(x, y, heading)                     # now
    fleet.trajectory("r01") -> [Sample(t, x, y, heading, speed, turn_rate, navstate), ...]  # with record=True
    fleet.drivers["r01"] -> RobotDriver (navstate, reason, path, plans); fleet.stats() -> {id: LoopStats}

Tags per robot NN (the `robot` template of tagdb.yaml, instances from robots.yaml):
    reads   rNN_xgoal, rNN_ygoal (m), rNN_status (a new goal, or status set true while parked,
            starts a trip) and every robot's rNN_xpos/ypos/heading/speed/navstate/radius (traffic)
    writes  rNN_xpos, rNN_ypos (m), rNN_heading (rad), rNN_speed (m/s), rNN_navstate
            (idle|planning|moving|blocked|arrived|failed), rNN_navreason, rNN_radius (m), and
            rNN_status: true when it sets off, false when within 0.5 m of the goal (or failed)
    remote  rNN_agent, rNN_report (written by `softplc robot-agent`), rNN_online

Every robot cycles on the runtime clock (100 ms by default; faster than real time under
SimClock, identical every run), plans with A* once per goal and on blockage (off the event loop),
follows the path with pure pursuit within its own speed limits capped by the floor's, and yields
by id order. Robots learn about each other only through the tags.
"""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.adapters.fleet.adapter import FleetAdapter
    from softplc.adapters.fleet.settings import FleetSettings
    from softplc.robotics.compat import (
        Compatibility,
        compatibility_matrix,
        compatible,
        compatible_robots,
        compatible_tasks,
        incompatibilities,
    )
    from softplc.robotics.controller import SpeedLimits
    from softplc.robotics.driver import DriverSettings, NavState, RobotDriver
    from softplc.robotics.floor import Floor
    from softplc.robotics.gridmap import OccupancyGrid, load_map
    from softplc.robotics.loop import Sample
    from softplc.robotics.planner import PathPlanner, Plan
    from softplc.robotics.robots import (
        Hardware,
        Pose,
        RobotFile,
        RobotSpec,
        TaskFile,
        TaskSpec,
        load_robots,
        load_tasks,
    )

# Public names and their modules, imported on first use (PEP 562): `softplc --help` imports
# softplc.adapters.fleet.cli and must not load numpy, scipy and the planner with it.
_MODULES = {
    "softplc.adapters.fleet.adapter": ("FleetAdapter",),
    "softplc.robotics.compat": (
        "Compatibility", "compatibility_matrix", "compatible", "compatible_robots", "compatible_tasks", "incompatibilities",
    ),
    "softplc.robotics.controller": ("SpeedLimits",),
    "softplc.robotics.driver": ("DriverSettings", "NavState", "RobotDriver"),
    "softplc.robotics.floor": ("Floor",),
    "softplc.robotics.gridmap": ("OccupancyGrid", "load_map"),
    "softplc.robotics.loop": ("Sample",),
    "softplc.robotics.planner": ("PathPlanner", "Plan"),
    "softplc.robotics.robots": ("Hardware", "Pose", "RobotFile", "RobotSpec", "TaskFile", "TaskSpec", "load_robots", "load_tasks"),
    "softplc.adapters.fleet.settings": ("FleetSettings",),
}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = [
    "Compatibility", "DriverSettings", "FleetAdapter", "FleetSettings", "Floor", "Hardware", "NavState",
    "OccupancyGrid", "PathPlanner", "Plan", "Pose", "RobotDriver", "RobotFile", "RobotSpec", "Sample",
    "SpeedLimits", "TaskFile", "TaskSpec", "compatibility_matrix", "compatible", "compatible_robots",
    "compatible_tasks", "incompatibilities", "load_map", "load_robots", "load_tasks",
]
