"""`softplc robot-agent`: a robot's driver on its own computer, a client of the plant's OPC UA server.

Building the parser imports nothing heavy (numpy, scipy, asyncua): the command imports what it
runs, so `softplc --help` stays fast.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Any

from softplc.clients.endpoints import endpoint_urls
from softplc.clients.robot_agent.signals import drive_until_signal
from softplc.protocols.opcua_names import DEFAULT_NAMESPACE
from softplc.robotics.layout import DEFAULT_MAP, DEFAULT_ROBOTS

EXIT_OK, EXIT_FAILURE = 0, 1
PASSWORD_ENV = "SOFTPLC_PASSWORD"
AGENT_NAMESPACE = DEFAULT_NAMESPACE


def add_commands(subparsers: Any) -> None:
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
    agent.add_argument("--endpoint", metavar="URL", type=endpoint_urls,
                       help="the runtime's OPC UA endpoint, opc.tcp://HOST:PORT/PATH; a redundant pair's two, comma separated: the agent follows the active")
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
        stopped_by = asyncio.run(drive_until_signal(agent, name, "the robot stands still, the session closes"))
    except AgentError as error:
        print(f"softplc {name}: {error}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:  # a Ctrl-C before the loop's handler was in place
        stopped_by = signal.SIGINT
    print(f"{name}: stopped", file=sys.stderr)
    return 130 if stopped_by == signal.SIGINT else EXIT_OK
