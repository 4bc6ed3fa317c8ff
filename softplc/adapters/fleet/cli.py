"""Fleet commands: `softplc compat`, `softplc plan`, `softplc robot-agent`.

Building the parser imports nothing heavy (numpy, scipy, asyncua): each command imports what
it runs, so `softplc --help` stays fast.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Any

from softplc.adapters.fleet.settings import DEFAULT_MAP, DEFAULT_ROBOTS, DEFAULT_TASKS

EXIT_OK, EXIT_FAILURE = 0, 1
PASSWORD_ENV = "SOFTPLC_PASSWORD"
AGENT_NAMESPACE = "urn:softplc:tags"  # = softplc.clients.robot_agent.agent.DEFAULT_NAMESPACE, which needs asyncua (a test keeps them equal)


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

    add_agent_command(subparsers)


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


# -- robot-agent ---------------------------------------------------------------------------------


def add_agent_command(subparsers: Any) -> None:
    agent = subparsers.add_parser(
        "robot-agent",
        help="run a robot's driver as a remote OPC UA client of a runtime",
        description="Drive one robot from its own computer: connect to the runtime's OPC UA server, "
        "register (robot id, name, hardware), follow the goals written to its tags and report its pose "
        "every cycle. Reconnects with backoff when the runtime restarts. The robot must be declared "
        "'driver: remote' in the runtime's robots.yaml.",
        epilog="Example: softplc robot-agent --endpoint opc.tcp://127.0.0.1:4840/softplc/ --robot r01 "
        f"--user r01 (password from ${PASSWORD_ENV}, --password-file or --password)",
    )
    agent.add_argument("--endpoint", metavar="URL", help="the runtime's OPC UA endpoint, opc.tcp://HOST:PORT/PATH")
    vda = agent.add_argument_group("as a VDA 5050 vehicle (any VDA 5050 master control drives it over MQTT; docs/vda5050.md)")
    vda.add_argument("--vda5050", metavar="BROKER", help="instead of --endpoint: the MQTT broker, mqtt://HOST:PORT (mqtts:// for TLS)")
    vda.add_argument("--protocol-version", choices=("2.0", "2.1"), default="2.0", help="VDA 5050 version (default 2.0)")
    vda.add_argument("--interface", default="uagv", metavar="NAME", help="interfaceName topic level (default uagv)")
    vda.add_argument("--map-id", default="factory", metavar="ID", help="the mapId it reports (the master's roadmap map_id; default factory)")
    vda.add_argument("--state-interval", type=float, default=30.0, metavar="S", help="state at least this often, seconds (default 30)")
    vda.add_argument("--mqtt-user", metavar="NAME", help="broker user name (password from --password-file, or $SOFTPLC_PASSWORD)")
    vda.add_argument("--ca-file", type=Path, metavar="PEM", help="CA certificates the broker's TLS certificate must chain to")
    agent.add_argument("--robot", required=True, metavar="ID", help="this robot's id in robots.yaml, e.g. r01")
    agent.add_argument("--robots", default=DEFAULT_ROBOTS, metavar="FILE", help=f"robots file (default {DEFAULT_ROBOTS})")
    agent.add_argument("--map", default=DEFAULT_MAP, metavar="FILE", help=f"map YAML (default {DEFAULT_MAP})")
    agent.add_argument("--cycle", type=float, default=0.1, metavar="S", help="control cycle in seconds (default 0.1)")
    agent.add_argument("--max-linear-speed", type=float, default=0.2, metavar="M/S", help="floor speed limit (default 0.2)")
    agent.add_argument("--max-angular-speed", type=float, default=0.4, metavar="RAD/S", help="floor turn-rate limit (default 0.4)")
    agent.add_argument("--namespace", default=AGENT_NAMESPACE, metavar="URI", help=f"namespace of the tags (default {AGENT_NAMESPACE})")
    login = agent.add_argument_group("login (an operator user; anonymous sessions may only read)")
    login.add_argument("--user", metavar="NAME", help="OPC UA user name")
    login.add_argument("--password", metavar="PW", help=f"password (visible to other users of this machine: prefer ${PASSWORD_ENV} or --password-file)")
    login.add_argument("--password-file", type=Path, metavar="FILE", help="read the password from the first line of FILE")
    login.add_argument("--certificate", type=Path, metavar="CERT", help="client certificate (DER or PEM) for a signed/encrypted channel; "
                       "without --user it also logs the robot in (softplc users add NAME --certificate ...)")
    login.add_argument("--private-key", type=Path, metavar="KEY", help="the certificate's private key (PEM)")
    login.add_argument("--security", choices=("None", "Basic256Sha256_Sign", "Basic256Sha256_SignAndEncrypt"),
                       help="security policy (default SignAndEncrypt with a certificate, None without)")
    agent.set_defaults(func=cmd_robot_agent)


def cmd_robot_agent(args: argparse.Namespace) -> int:
    if args.vda5050 is not None:
        from softplc.clients.robot_agent.vda5050.cli import run_vehicle

        return run_vehicle(args)
    if args.endpoint is None:
        print("softplc robot-agent: give --endpoint opc.tcp://HOST:PORT/PATH (or --vda5050 mqtt://HOST:PORT for a VDA 5050 vehicle)",
              file=sys.stderr)
        return 2
    from softplc.clients.robot_agent.agent import AgentError, Credentials, RobotAgent
    from softplc.robotics.controller import SpeedLimits
    from softplc.robotics.floor import Floor
    from softplc.robotics.gridmap import load_map
    from softplc.robotics.robots import load_robots, unknown_id_message

    if (args.certificate is None) != (args.private_key is None):
        print("softplc robot-agent: --certificate and --private-key go together", file=sys.stderr)
        return 1
    password = args.password
    if args.password_file is not None:
        try:
            password = args.password_file.read_text(encoding="utf-8").splitlines()[0]
        except (OSError, IndexError) as error:
            print(f"softplc robot-agent: cannot read --password-file {args.password_file}: {error}", file=sys.stderr)
            return 1
    if password is None:
        password = os.environ.get(PASSWORD_ENV)
    if args.user and password is None:
        print(f"softplc robot-agent: --user {args.user} needs a password (${PASSWORD_ENV}, --password-file or --password)", file=sys.stderr)
        return 1
    security = args.security or ("Basic256Sha256_SignAndEncrypt" if args.certificate else "None")
    if security != "None" and args.certificate is None:
        print(f"softplc robot-agent: --security {security} needs --certificate and --private-key", file=sys.stderr)
        return 1
    robots = load_robots(args.robots)  # ConfigError → FILE:LINE:COL, printed by the CLI
    if args.robot not in robots.ids:
        print(f"softplc robot-agent: {unknown_id_message('robot', args.robot, robots.ids)} (in {args.robots})", file=sys.stderr)
        return 1
    floor = Floor(load_map(args.map))
    spec = robots[args.robot]
    limits = SpeedLimits(min(spec.max_linear_speed, args.max_linear_speed), min(spec.max_angular_speed, args.max_angular_speed))
    credentials = Credentials(args.user, password, args.certificate, args.private_key, security)
    agent = RobotAgent(args.endpoint, args.robot, robots, floor, credentials=credentials, namespace=args.namespace,
                       cycle=args.cycle, limits=limits)
    if getattr(args, "verbose", 0) < 2:
        # asyncua logs a traceback for every lost connection; the agent says it in one line.
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)
    name = f"robot-agent {args.robot}"
    print(f"{name} ({spec.name}): connecting to {args.endpoint}; Ctrl-C to stop", file=sys.stderr)
    try:
        stopped_by = asyncio.run(_drive_until_signal(agent, name))
    except AgentError as error:
        print(f"softplc {name}: {error}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:  # a Ctrl-C before the loop's handler was in place
        stopped_by = signal.SIGINT
    print(f"{name}: stopped", file=sys.stderr)
    return 130 if stopped_by == signal.SIGINT else EXIT_OK


async def _drive_until_signal(agent: Any, name: str) -> int:
    """Run the agent until SIGTERM or SIGINT (announced, the session closed); the signal's number."""
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    assert task is not None
    received: list[int] = []

    def stop(signum: int) -> None:
        if not received:
            print(f"{name}: {signal.Signals(signum).name} received, stopping (the robot stands still, the session closes)",
                  file=sys.stderr)
            task.cancel()
        received.append(signum)

    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, stop, signum)
    try:
        await agent.run()
    except asyncio.CancelledError:
        if not received:
            raise
    return received[0] if received else 0
