"""`softplc robot-agent --vda5050 mqtt://HOST:PORT --robot r04`: run one robot as a VDA 5050 vehicle until Ctrl-C."""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import sys
from urllib.parse import urlparse

from softplc.clients.robot_agent.signals import drive_until_signal
from softplc.protocols.mqtt_settings import DEFAULT_PORTS, MqttSettings, TlsSettings

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2


def run_vehicle(args: argparse.Namespace) -> int:
    """The robot-agent command with --vda5050 (see softplc/adapters/fleet/cli.py for its options)."""
    from softplc.clients.robot_agent.vda5050.agent import VehicleAgent
    from softplc.robotics.controller import SpeedLimits
    from softplc.robotics.floor import Floor
    from softplc.robotics.gridmap import load_map
    from softplc.robotics.robots import load_robots, unknown_id_message

    url = urlparse(args.vda5050)
    if url.scheme not in DEFAULT_PORTS or not url.hostname:
        print(f"softplc robot-agent: --vda5050 {args.vda5050!r}: write mqtt://HOST:PORT or mqtts://HOST:PORT", file=sys.stderr)
        return EXIT_USAGE
    robots = load_robots(args.robots)
    if args.robot not in robots.ids:
        print(f"softplc robot-agent: {unknown_id_message('robot', args.robot, robots.ids)} (in {args.robots})", file=sys.stderr)
        return EXIT_FAILURE
    spec = robots[args.robot]
    tls = TlsSettings(ca_file=args.ca_file) if url.scheme == "mqtts" or args.ca_file else None
    password_file = args.password_file
    if args.mqtt_user and password_file is None and os.environ.get("SOFTPLC_PASSWORD") is None:
        print("softplc robot-agent: --mqtt-user needs a password (--password-file or $SOFTPLC_PASSWORD)", file=sys.stderr)
        return EXIT_USAGE
    settings = _Settings(host=url.hostname, port=url.port or DEFAULT_PORTS[url.scheme], client_id=f"softplc-{spec.id}",
                         username=args.mqtt_user, password_file=password_file, tls=tls, keepalive=15.0, protocol="3.1.1")
    limits = SpeedLimits(min(spec.max_linear_speed, args.max_linear_speed), min(spec.max_angular_speed, args.max_angular_speed))
    agent = VehicleAgent(spec, Floor(load_map(args.map)), settings, interface=args.interface, version=args.protocol_version,
                         map_id=args.map_id, cycle=args.cycle, limits=limits, state_interval=args.state_interval)
    if getattr(args, "verbose", 0) < 1:
        logging.getLogger("softplc.protocols.mqtt").setLevel(logging.WARNING)
    name = f"robot-agent {spec.id}"
    print(f"{name} ({spec.name}): VDA 5050 {args.protocol_version} vehicle {agent.manufacturer}/{agent.serial_number} "
          f"on {args.vda5050}; Ctrl-C to stop", file=sys.stderr)
    try:
        stopped_by = asyncio.run(drive_until_signal(agent, name))
    except KeyboardInterrupt:
        stopped_by = signal.SIGINT
    print(f"{name}: stopped (said OFFLINE)", file=sys.stderr)
    return 130 if stopped_by == signal.SIGINT else EXIT_OK


class _Settings(MqttSettings):
    """The broker settings of the command line: the password may come from $SOFTPLC_PASSWORD."""

    def password(self) -> str | None:
        if self.password_file is None:
            return os.environ.get("SOFTPLC_PASSWORD") if self.username else None
        return super().password()
