"""Which adapters `softplc run` starts around the core, from the `servers:` section and flags.

Each adapter module contributes its command-line flags to `run` (`add_run_arguments`) and
builds itself from the configuration (`build_adapters`). The core never imports this module.

Every protocol server is on by default, on loopback and its default port; `run` says which
ones are off and how to turn them on (`servers_off`). Under `--sim` a server whose port is not given on the
command line binds port 0 (any free port, printed in its `serving:` line), so a simulation
never collides with the plant running beside it: `simulation_port()` is that one rule.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from softplc.config import PlantConfig
    from softplc.adapters.modbus.settings import ModbusSettings
    from softplc.adapters.opcua.settings import OpcUaSettings
    from softplc.app.runtime import Adapter

def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `softplc run` that belong to adapters."""
    group = parser.add_argument_group("servers")
    group.add_argument("--no-servers", action="store_true", help="start no protocol server (scan only)")
    # Modbus TCP (softplc.adapters.modbus)
    from softplc.adapters.modbus.settings import host_name as modbus_host
    from softplc.adapters.modbus.settings import port_number as modbus_port

    group.add_argument("--modbus-host", type=modbus_host, metavar="HOST", help="Modbus TCP bind address (default servers.modbus.host, 127.0.0.1)")
    group.add_argument("--modbus-port", type=modbus_port, metavar="PORT", help="Modbus TCP port (default servers.modbus.port, 5020; 0 = any free port, the default under --sim)")
    group.add_argument("--no-modbus", action="store_true", help="do not start the Modbus TCP server")
    # OPC UA (softplc.adapters.opcua)
    group.add_argument("--opcua-endpoint", metavar="URL", help="OPC UA endpoint, e.g. opc.tcp://0.0.0.0:4840/softplc/ (default servers.opcua.endpoint; port 0 = any free port, the default under --sim)")
    group.add_argument("--opcua-security", metavar="LIST", help="comma-separated policies: None, Basic256Sha256_Sign, Basic256Sha256_SignAndEncrypt")
    group.add_argument("--opcua-anonymous", choices=("off", "viewer"), help="anonymous OPC UA sessions: refused, or read-only")
    group.add_argument("--opcua-users", type=Path, metavar="FILE", help="OPC UA users file (default servers.opcua.users_file, STATE_DIR/users.yaml)")
    group.add_argument("--no-opcua", action="store_true", help="do not start the OPC UA server")
    # Web HMI (softplc.adapters.hmi)
    from softplc.adapters.hmi.settings import host_name as hmi_host
    from softplc.adapters.hmi.settings import port_number as hmi_port

    hmi = parser.add_argument_group("web HMI")
    hmi.add_argument("--hmi-host", type=hmi_host, metavar="HOST", help="HMI bind address (default servers.hmi.host, 127.0.0.1)")
    hmi.add_argument("--hmi-port", type=hmi_port, metavar="PORT", help="HMI port (default servers.hmi.port, 8080; 0 = any free port)")
    hmi.add_argument("--hmi-anonymous", choices=("off", "viewer"), help="visitors who have not logged in: refused, or read-only")
    hmi.add_argument("--hmi-tls", action="store_true", default=None, help="serve the HMI over HTTPS (certificate made in STATE_DIR/hmi/tls)")
    hmi.add_argument("--hmi-open", action="store_true", help="open the HMI in a browser once it serves (when there is a screen)")
    hmi.add_argument("--no-hmi", action="store_true", help="do not start the web HMI")
    # Robot fleet (softplc.adapters.fleet)
    robots = parser.add_argument_group("robots")
    robots.add_argument("--no-fleet", action="store_true", help="do not drive the robots of the fleet: section")
    # Historian (softplc.adapters.history)
    history = parser.add_argument_group("history")
    history.add_argument("--no-history", action="store_true", help="record no history (the history: section)")
    # Audit trail (softplc.adapters.audit)
    audit = parser.add_argument_group("audit trail")
    audit.add_argument("--no-audit", action="store_true", help="keep no audit trail of writes and commands for this run (the audit: section)")


def simulation_port(args: argparse.Namespace | None, *flags: str) -> int | None:
    """0 (any free port) for a server of a `--sim` run none of whose `flags` is on the command line, else None.

    None means: bind what the configuration (or the flag) says. Every server adapter asks this,
    with the flags that set its port (e.g. "modbus_port"), so a simulation beside a running
    plant never fails with "address already in use"; an explicit flag still wins.
    """
    if args is None or not getattr(args, "sim", False):
        return None
    if any(getattr(args, flag, None) is not None for flag in flags):
        return None
    return 0


def build_adapters(config: PlantConfig, args: argparse.Namespace | None = None) -> list[Adapter]:
    """The adapters to start for this plant, honouring command-line overrides in `args`.

    Raises one ConfigError with the problems of every adapter's section, not just the first's.
    """
    from softplc.config.yamlsource import ConfigError, Problem

    # The audit trail first: it listens before any client can write, and stops last. Alarms
    # next: the OPC UA server lists them (as conditions) when it starts; the historian before it
    # too: the server asks `history.tags` which tags are historized as it builds its nodes.
    builders = [_audit, _alarms, _fleet, _history]  # none of them is a server: --no-servers keeps them
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


def servers_off(config: PlantConfig, args: argparse.Namespace | None = None) -> list[str]:
    """The protocol servers this run does not start, each with why and how to turn it on."""
    if args is not None and getattr(args, "no_servers", False):
        return ["OPC UA, Modbus TCP and the web HMI (--no-servers): run without it to serve them"]
    off = []
    if getattr(args, "no_opcua", False):
        off.append("OPC UA (--no-opcua)")
    elif not _opcua_settings(config, args).enabled:
        off.append(f"OPC UA (servers.opcua.enabled: false in {config.path.name}): set enabled: true to serve it")
    if getattr(args, "no_modbus", False):
        off.append("Modbus TCP (--no-modbus)")
    elif not _modbus_settings(config, args).enabled:
        off.append(f"Modbus TCP (servers.modbus.enabled: false in {config.path.name}): set enabled: true, or give --modbus-port PORT, to serve it")
    if getattr(args, "no_hmi", False):
        off.append("the web HMI (--no-hmi)")
    else:
        from softplc.adapters.hmi.settings import HmiSettings

        if not HmiSettings.from_config(config).enabled:
            off.append(f"the web HMI (servers.hmi.enabled: false in {config.path.name}): set enabled: true to serve it")
    return off


def _modbus_settings(config: PlantConfig, args: argparse.Namespace | None) -> ModbusSettings:
    from softplc.adapters.modbus.settings import ModbusSettings

    settings = ModbusSettings.from_servers(config.servers).override(
        host=getattr(args, "modbus_host", None),
        port=getattr(args, "modbus_port", None),
        disable=bool(getattr(args, "no_modbus", False)),
    )
    port = simulation_port(args, "modbus_port")
    return settings if port is None else dataclasses.replace(settings, port=port)


def _modbus(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    settings = _modbus_settings(config, args)
    if not settings.enabled:  # its section, pinned addresses included, was checked with the configuration
        return []
    from softplc.adapters.modbus.server import ModbusAdapter

    return [ModbusAdapter(config, settings)]


def _opcua_settings(config: PlantConfig, args: argparse.Namespace | None) -> OpcUaSettings:
    from softplc.adapters.opcua.settings import OpcUaSettings, SettingsError
    from softplc.config.yamlsource import ConfigError

    try:
        settings = OpcUaSettings.from_section(config.section("servers", "opcua"), config.base_dir)
    except SettingsError as error:
        raise ConfigError([config.problem(("servers", "opcua", error.key), str(error))]) from None
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
    port = simulation_port(args, "opcua_endpoint")
    return settings if port is None else settings.with_port(port)


def _opcua(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    settings = _opcua_settings(config, args)
    if not settings.enabled or bool(getattr(args, "no_opcua", False)):
        return []
    from softplc.adapters.opcua.server import OpcUaServer

    return [OpcUaServer(settings)]


def _alarms(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.alarms.settings import AlarmSettings, configured

    if not configured(config):
        return []
    from softplc.adapters.alarms.adapter import AlarmsAdapter

    return [AlarmsAdapter(AlarmSettings.from_config(config))]  # ConfigError: located problems of alarms:


def _fleet(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.fleet.settings import FleetSettings

    if not FleetSettings.configured(config) or bool(getattr(args, "no_fleet", False)):
        return []
    if not FleetSettings.from_config(config).enabled:
        return []
    from softplc.adapters.fleet.adapter import FleetAdapter

    return [FleetAdapter.from_config(config)]


def _audit(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.audit.settings import AuditSettings

    settings = AuditSettings.from_config(config)  # checked by its section owner (softplc.adapters.audit.section)
    if not settings.enabled or bool(getattr(args, "no_audit", False)):
        return []
    from softplc.adapters.audit.recorder import AuditRecorder

    return [AuditRecorder(settings, config.name)]


# -- historian (softplc.adapters.history) ----------------------------------------------------


def _history(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.history.section import tag_rules
    from softplc.adapters.history.settings import HistorySettings
    from softplc.engine.systags import runtime_tag_definitions

    rules = tag_rules(config)
    if not HistorySettings.configured(config) and not rules:
        return []
    definitions = [*config.tags, *runtime_tag_definitions(config)]
    settings = HistorySettings.from_config(config, rules)  # checked by its section owner (softplc.adapters.history.section)
    if not settings.enabled or bool(getattr(args, "no_history", False)):
        return []
    if bool(getattr(args, "sim", False)) and not settings.sim:
        return []
    from softplc.adapters.history.recorder import HistoryRecorder

    policies = settings.policies(definitions)
    types = {d.name: (d.type.value, d.unit) for d in definitions if d.name in policies}
    return [HistoryRecorder(settings, config.name, policies, types)]


def _hmi(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.hmi.settings import HmiSettings  # its sections are checked by their owner (softplc.adapters.hmi.section)

    settings = HmiSettings.from_config(config).override(
        host=getattr(args, "hmi_host", None),
        port=getattr(args, "hmi_port", None),
        anonymous=getattr(args, "hmi_anonymous", None),
        tls=getattr(args, "hmi_tls", None),
        open_browser=bool(getattr(args, "hmi_open", False)) or None,
    )
    port = simulation_port(args, "hmi_port")
    if port is not None:
        settings = dataclasses.replace(settings, port=port)
    if not settings.enabled or bool(getattr(args, "no_hmi", False)):
        return []
    from softplc.adapters.hmi.server import HmiServer
    from softplc.adapters.metrics.settings import MetricsSettings

    hmi = HmiServer(config, settings)
    metrics = MetricsSettings.from_config(config)
    if not metrics.enabled:
        return [hmi]
    from softplc.adapters.metrics.adapter import MetricsAdapter

    return [MetricsAdapter(hmi, metrics), hmi]  # /metrics on the HMI's server; ready before it listens
