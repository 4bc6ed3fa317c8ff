"""The Modbus TCP server's manifest (softplc.config.manifest): its section, flags, builder, commands and figures."""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING

from softplc.adapters.modbus.section import SECTION
from softplc.config.manifest import Manifest, counter, flag, gauge, simulation_port

if TYPE_CHECKING:
    from softplc.adapters.modbus.settings import ModbusSettings
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from softplc.util.addresses import host_name, port_number

    group = parser.add_argument_group("Modbus TCP server")
    group.add_argument("--modbus-host", type=host_name, metavar="HOST", help="Modbus TCP bind address (default servers.modbus.host, 127.0.0.1)")
    group.add_argument("--modbus-port", type=port_number, metavar="PORT", help="Modbus TCP port (default servers.modbus.port, 5020; 0 = any free port, the default under --sim)")
    group.add_argument("--no-modbus", action="store_true", help="do not start the Modbus TCP server")


def settings(config: PlantConfig, args: argparse.Namespace | None) -> ModbusSettings:
    """`servers.modbus` with the command line's overrides."""
    from softplc.adapters.modbus.settings import ModbusSettings

    resolved = ModbusSettings.from_servers(config.servers).override(
        host=flag(args, "modbus_host"),
        port=flag(args, "modbus_port"),
        disable=bool(flag(args, "no_modbus", False)),
    )
    port = simulation_port(args, "modbus_port")
    return resolved if port is None else dataclasses.replace(resolved, port=port)


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    resolved = settings(config, args)
    if not resolved.enabled:  # its section, pinned addresses included, was checked with the configuration
        return []
    from softplc.adapters.modbus.server import ModbusAdapter

    return [ModbusAdapter(config, resolved)]


def off(config: PlantConfig, args: argparse.Namespace | None) -> str | None:
    if flag(args, "no_modbus", False):
        return "Modbus TCP (--no-modbus)"
    if not settings(config, args).enabled:
        return f"Modbus TCP (servers.modbus.enabled: false in {config.path.name}): set enabled: true, or give --modbus-port PORT, to serve it"
    return None


MANIFEST = Manifest(
    name="modbus",
    title="Modbus TCP",
    order=60,
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    server=True,
    off=off,
    commands=("softplc.adapters.modbus.cli",),
    figures={
        "connections": gauge("softplc_modbus_connections", "Modbus TCP client connections open"),
        "connections_refused": counter("softplc_modbus_connections_refused_total", "Modbus TCP connections refused (max_connections)"),
        "connections_closed": counter("softplc_modbus_connections_closed_total", "Modbus TCP connections the server closed, by reason (idle, framing)", "reason"),
        "requests": counter("softplc_modbus_requests_total", "Modbus TCP requests answered, by function code and result (ok, exception)", "function", "result"),
    },
)
