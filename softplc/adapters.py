"""Which adapters `softplc run` starts around the core, from the `servers:` section and flags.

Each adapter module contributes its command-line flags to `run` (`add_run_arguments`) and
builds itself from the configuration (`build_adapters`). The core never imports this module.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from softplc.config import PlantConfig
    from softplc.runtime import Adapter


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `softplc run` that belong to adapters."""
    group = parser.add_argument_group("servers")
    group.add_argument("--no-servers", action="store_true", help="start no protocol server (scan only)")
    # Modbus TCP (softplc.modbus)
    from softplc.modbus.settings import host_name as modbus_host
    from softplc.modbus.settings import port_number as modbus_port

    group.add_argument("--modbus-host", type=modbus_host, metavar="HOST", help="Modbus TCP bind address (default servers.modbus.host, 127.0.0.1)")
    group.add_argument("--modbus-port", type=modbus_port, metavar="PORT", help="Modbus TCP port (default servers.modbus.port, 5020; 0 = any free port)")
    group.add_argument("--no-modbus", action="store_true", help="do not start the Modbus TCP server")
    # OPC UA (softplc.opcua)
    group.add_argument("--opcua-endpoint", metavar="URL", help="OPC UA endpoint, e.g. opc.tcp://0.0.0.0:4840/softplc/ (default servers.opcua.endpoint; port 0 = any free port)")
    group.add_argument("--opcua-security", metavar="LIST", help="comma-separated policies: None, Basic256Sha256_Sign, Basic256Sha256_SignAndEncrypt")
    group.add_argument("--opcua-anonymous", choices=("off", "viewer"), help="anonymous OPC UA sessions: refused, or read-only")
    group.add_argument("--opcua-users", type=Path, metavar="FILE", help="OPC UA users file (default servers.opcua.users_file, STATE_DIR/users.yaml)")
    group.add_argument("--no-opcua", action="store_true", help="do not start the OPC UA server")
    # Web HMI (softplc.hmi) -- HMI branch: moves onto the config registry at merge
    from softplc.hmi.settings import host_name as hmi_host
    from softplc.hmi.settings import port_number as hmi_port

    hmi = parser.add_argument_group("web HMI")
    hmi.add_argument("--hmi-host", type=hmi_host, metavar="HOST", help="HMI bind address (default servers.hmi.host, 127.0.0.1)")
    hmi.add_argument("--hmi-port", type=hmi_port, metavar="PORT", help="HMI port (default servers.hmi.port, 8080; 0 = any free port)")
    hmi.add_argument("--hmi-anonymous", choices=("off", "viewer"), help="visitors who have not logged in: refused, or read-only")
    hmi.add_argument("--hmi-tls", action="store_true", default=None, help="serve the HMI over HTTPS (certificate made in STATE_DIR/hmi/tls)")
    hmi.add_argument("--hmi-open", action="store_true", help="open the HMI in a browser once it serves (when there is a screen)")
    hmi.add_argument("--no-hmi", action="store_true", help="do not start the web HMI")
    # Robot fleet (softplc.fleet)
    robots = parser.add_argument_group("robots")
    robots.add_argument("--no-fleet", action="store_true", help="do not drive the robots of the fleet: section")


def build_adapters(config: PlantConfig, args: argparse.Namespace | None = None) -> list[Adapter]:
    """The adapters to start for this plant, honouring command-line overrides in `args`.

    Raises one ConfigError with the problems of every adapter's section, not just the first's.
    """
    from softplc.yamlsource import ConfigError, Problem

    builders = [_fleet]  # robots are not servers: --no-servers keeps them
    if not (args is not None and getattr(args, "no_servers", False)):
        builders += [_opcua, _modbus, _hmi]
    adapters: list[Adapter] = []
    problems: list[Problem] = []
    for build in builders:
        try:
            adapters.extend(build(config, args))
        except ConfigError as error:
            problems.extend(error.problems)
    if problems:
        raise ConfigError(problems)
    return adapters


def _modbus(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.modbus.settings import ModbusSettings

    settings = ModbusSettings.from_servers(config.servers).override(
        host=getattr(args, "modbus_host", None),
        port=getattr(args, "modbus_port", None),
        disable=bool(getattr(args, "no_modbus", False)),
    )
    if not settings.enabled:
        if any("modbus" in tag.options for tag in config.tags):
            from softplc.modbus.address_map import build_address_map

            build_address_map(config, settings)  # addresses pinned in the tags are checked even while the server is off
        return []
    from softplc.modbus.server import ModbusAdapter

    return [ModbusAdapter(config, settings)]


def _opcua(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.opcua.settings import OpcUaSettings, SettingsError
    from softplc.yamlsource import ConfigError, Location, Problem

    try:
        settings = OpcUaSettings.from_section(config.servers.get("opcua"), config.base_dir)
    except SettingsError as error:
        path = ("servers", "opcua", error.key)
        where = config.source.problem(path, str(error)) if config.source else Problem(Location(str(config.path), 1, 1), str(error))
        raise ConfigError([where]) from None
    security = getattr(args, "opcua_security", None)
    try:
        settings = settings.with_overrides(
            endpoint=getattr(args, "opcua_endpoint", None),
            security=tuple(p.strip() for p in security.split(",") if p.strip()) if security else None,
            anonymous=getattr(args, "opcua_anonymous", None),
            users_file=getattr(args, "opcua_users", None),
        )
    except SettingsError as error:
        raise SystemExit(f"softplc: --opcua-{error.key.replace('_file', 's')}: {error}") from None
    if not settings.enabled or bool(getattr(args, "no_opcua", False)):
        return []
    from softplc.opcua.server import OpcUaServer

    return [OpcUaServer(settings)]


def _fleet(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.fleet.settings import FleetSettings

    if not FleetSettings.configured(config) or bool(getattr(args, "no_fleet", False)):
        return []
    if not FleetSettings.from_config(config).enabled:
        return []
    from softplc.fleet.adapter import FleetAdapter

    return [FleetAdapter.from_config(config)]


def _hmi(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    # HMI branch: the settings and checks live in softplc.hmi.settings (plain data and functions).
    from softplc.hmi.settings import HmiSettings, hmi_problems
    from softplc.yamlsource import ConfigError

    problems = hmi_problems(config)  # views are checked even while the HMI is off
    if problems:
        raise ConfigError(problems)
    settings = HmiSettings.from_config(config).override(
        host=getattr(args, "hmi_host", None),
        port=getattr(args, "hmi_port", None),
        anonymous=getattr(args, "hmi_anonymous", None),
        tls=getattr(args, "hmi_tls", None),
        open_browser=bool(getattr(args, "hmi_open", False)) or None,
    )
    if not settings.enabled or bool(getattr(args, "no_hmi", False)):
        return []
    from softplc.hmi.server import HmiServer

    return [HmiServer(config, settings)]
