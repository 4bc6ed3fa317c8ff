"""Fleet commands: `softplc compat`, `softplc plan` (`softplc robot-agent` is a client: softplc/clients/robot_agent/cli.py).

Building the parser imports nothing heavy (numpy, scipy, asyncua): each command imports what
it runs, so `softplc --help` stays fast.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from softplc.adapters.fleet.settings import DEFAULT_MAP, DEFAULT_ROBOTS, DEFAULT_TASKS

EXIT_OK, EXIT_FAILURE = 0, 1


def add_commands(subparsers: Any) -> None:
    compat = subparsers.add_parser(
        "compat",
        help="which robots can serve which tasks",
        description="Print the robot-task compatibility matrix (thesis §4.7.2): a robot serves a task when "
        "its size is within the task's maxima, its load capacity and speeds reach the task's minima and "
        "it has all the hardware the task requires.",
        epilog="Examples: softplc compat | softplc compat --robots robots/case2-sim1/robots.yaml "
        "--tasks robots/case2-sim1/tasks.yaml --format json",
    )
    compat.add_argument("--robots", default=DEFAULT_ROBOTS, metavar="FILE", help=f"robots file (default {DEFAULT_ROBOTS})")
    compat.add_argument("--tasks", default=DEFAULT_TASKS, metavar="FILE", help=f"tasks file (default {DEFAULT_TASKS})")
    compat.add_argument("--format", choices=("table", "json"), default="table")
    compat.set_defaults(func=cmd_compat)

    plan = subparsers.add_parser(
        "plan",
        help="plan a robot's path on a map",
        description="Plan a path with A* on an occupancy map for a robot of the given radius, and print it "
        "(or why there is none).",
        epilog="Example: softplc plan 7.925 5.925 18.5 7.5 --radius 0.18",
    )
    # Four positionals, not nargs=4 with a tuple metavar: argparse (Python 3.11) crashes printing help for that.
    for name, text in (("x0", "start x"), ("y0", "start y"), ("x1", "goal x"), ("y1", "goal y")):
        plan.add_argument(name, type=float, metavar=name.upper(), help=f"{text}, metres")
    plan.add_argument("--map", default=DEFAULT_MAP, metavar="FILE", help=f"map YAML (default {DEFAULT_MAP})")
    plan.add_argument("--radius", type=float, default=0.18, metavar="M", help="robot radius in metres (default 0.18, a TurtleBot)")
    plan.add_argument("--resolution", type=float, default=0.1, metavar="M", help="planning grid cell size (default 0.1)")
    plan.add_argument("--format", choices=("table", "json"), default="table")
    plan.set_defaults(func=cmd_plan)



def cmd_compat(args: argparse.Namespace) -> int:
    from softplc.robotics.compat import Compatibility
    from softplc.util.console import print_table

    compat = Compatibility.load(args.robots, args.tasks)
    matrix = compat.matrix()
    if args.format == "json":
        document = {
            "robots": {robot.id: compat.tasks_for(robot.id) for robot in compat.robots},
            "tasks": {task.id: compat.robots_for(task.id) for task in compat.tasks},
            "matrix": matrix,
            "reasons": {r.id: {t.id: compat.why_not(r.id, t.id) for t in compat.tasks if not matrix[r.id][t.id]} for r in compat.robots},
        }
        print(json.dumps(document, indent=2))
        return EXIT_OK
    header = ["robot", "name", *[task.id for task in compat.tasks], "can serve"]
    rows = []
    for robot in compat.robots:
        cells = ["yes" if matrix[robot.id][task.id] else "no" for task in compat.tasks]
        rows.append([robot.id, robot.name, *cells, ", ".join(compat.tasks_for(robot.id)) or "none"])
    print_table(rows, header)
    print()
    for task in compat.tasks:
        team = compat.robots_for(task.id)
        size = f"team of at most {task.max_team_size}" if task.max_team_size > 0 else "any team size"
        print(f"{task.id} ({task.name}): {', '.join(team) or 'no robot'}; {size}")
    for robot in compat.robots:
        for task in compat.tasks:
            reasons = compat.why_not(robot.id, task.id)
            if reasons:
                print(f"{robot.id} cannot serve {task.id}: {'; '.join(reasons)}")
    return EXIT_OK


def cmd_plan(args: argparse.Namespace) -> int:
    from softplc.robotics.gridmap import load_map
    from softplc.robotics.planner import PathPlanner

    grid = load_map(args.map)
    planner = PathPlanner(grid, args.radius, resolution=args.resolution)
    x0, y0, x1, y1 = args.x0, args.y0, args.x1, args.y1
    plan = planner.plan((x0, y0), (x1, y1))
    if args.format == "json":
        print(json.dumps({"ok": plan.ok, "reason": plan.reason, "length_m": plan.length, "grid_length_m": plan.grid_length,
                          "expanded": plan.expanded, "ms": plan.seconds * 1000, "path": plan.path}, indent=2))
        return EXIT_OK if plan.ok else EXIT_FAILURE
    if not plan.ok:
        print(f"no path: {plan.reason}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"path of {plan.length:.2f} m ({len(plan.path)} waypoints), {plan.expanded} cells expanded in {plan.seconds * 1000:.1f} ms")
    for x, y in plan.path:
        print(f"  {x:7.3f} {y:7.3f}")
    return EXIT_OK
