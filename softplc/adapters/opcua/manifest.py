"""The OPC UA server's manifest (softplc.config.manifest): its section, flags, builder, commands and figures."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from softplc.adapters.opcua.section import SECTION
from softplc.config.manifest import Manifest, flag, gauge, simulation_port

if TYPE_CHECKING:
    from softplc.adapters.opcua.settings import OpcUaSettings
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("OPC UA server")
    group.add_argument("--opcua-endpoint", metavar="URL", help="OPC UA endpoint, e.g. opc.tcp://0.0.0.0:4840/softplc/ (default servers.opcua.endpoint; port 0 = any free port, the default under --sim)")
    group.add_argument("--opcua-security", metavar="LIST", help="comma-separated policies: None, Basic256Sha256_Sign, Basic256Sha256_SignAndEncrypt")
    group.add_argument("--opcua-anonymous", choices=("off", "viewer"), help="anonymous OPC UA sessions: refused, or read-only")
    group.add_argument("--opcua-users", type=Path, metavar="FILE", help="OPC UA users file (default servers.opcua.users_file, STATE_DIR/users.yaml)")
    group.add_argument("--no-opcua", action="store_true", help="do not start the OPC UA server")


def settings(config: PlantConfig, args: argparse.Namespace | None) -> OpcUaSettings:
    """`servers.opcua` with the command line's overrides."""
    from softplc.adapters.opcua.settings import OpcUaSettings, SettingsError
    from softplc.config.yamlsource import ConfigError

    try:
        resolved = OpcUaSettings.from_section(config.section("servers", "opcua"), config.base_dir)
    except SettingsError as error:
        raise ConfigError([config.problem(("servers", "opcua", error.key), str(error))]) from None
    security = flag(args, "opcua_security")
    try:
        resolved = resolved.with_overrides(
            endpoint=flag(args, "opcua_endpoint"),
            security=tuple(p.strip() for p in security.split(",") if p.strip()) if security else None,
            anonymous=flag(args, "opcua_anonymous"),
            users_file=flag(args, "opcua_users"),
        )
    except SettingsError as error:
        raise SystemExit(f"softplc: --opcua-{error.key.replace('_file', 's')}: {error}") from None
    port = simulation_port(args, "opcua_endpoint")
    return resolved if port is None else resolved.with_port(port)


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    resolved = settings(config, args)
    if not resolved.enabled or flag(args, "no_opcua", False):
        return []
    from softplc.adapters.opcua.server import OpcUaServer

    return [OpcUaServer(resolved)]


def off(config: PlantConfig, args: argparse.Namespace | None) -> str | None:
    if flag(args, "no_opcua", False):
        return "OPC UA (--no-opcua)"
    if not settings(config, args).enabled:
        return f"OPC UA (servers.opcua.enabled: false in {config.path.name}): set enabled: true to serve it"
    return None


MANIFEST = Manifest(
    name="opcua",
    title="OPC UA",
    order=50,  # after the alarms and the historian: it lists their conditions and historized tags as it builds its nodes
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    server=True,
    off=off,
    commands=("softplc.adapters.opcua.cli",),
    figures={
        "sessions": gauge("softplc_opcua_sessions", "OPC UA sessions open (activated)"),
        "subscriptions": gauge("softplc_opcua_subscriptions", "OPC UA subscriptions"),
        "monitored_items": gauge("softplc_opcua_monitored_items", "OPC UA monitored items of every subscription"),
    },
)
