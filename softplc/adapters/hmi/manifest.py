"""The web HMI's manifest (softplc.config.manifest): its sections, flags, builder and figures."""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING

from softplc.adapters.hmi.section import SECTIONS
from softplc.config.manifest import Manifest, counter, flag, gauge, simulation_port

if TYPE_CHECKING:
    from softplc.adapters.hmi.settings import HmiSettings
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from softplc.util.addresses import host_name, port_number

    group = parser.add_argument_group("web HMI")
    group.add_argument("--hmi-host", type=host_name, metavar="HOST", help="HMI bind address (default servers.hmi.host, 127.0.0.1)")
    group.add_argument("--hmi-port", type=port_number, metavar="PORT", help="HMI port (default servers.hmi.port, 8080; 0 = any free port)")
    group.add_argument("--hmi-anonymous", choices=("off", "viewer"), help="visitors who have not logged in: refused, or read-only")
    group.add_argument("--hmi-tls", action="store_true", default=None, help="serve the HMI over HTTPS (certificate made in STATE_DIR/hmi/tls)")
    group.add_argument("--hmi-open", action="store_true", help="open the HMI in a browser once it serves (when there is a screen)")
    group.add_argument("--no-hmi", action="store_true", help="do not start the web HMI")


def settings(config: PlantConfig, args: argparse.Namespace | None) -> HmiSettings:
    """`servers.hmi` with the command line's overrides."""
    from softplc.adapters.hmi.settings import HmiSettings  # its sections are checked by their owner (section.py)

    resolved = HmiSettings.from_config(config).override(
        host=flag(args, "hmi_host"),
        port=flag(args, "hmi_port"),
        anonymous=flag(args, "hmi_anonymous"),
        tls=flag(args, "hmi_tls"),
        open_browser=bool(flag(args, "hmi_open", False)) or None,
    )
    port = simulation_port(args, "hmi_port")
    return resolved if port is None else dataclasses.replace(resolved, port=port)


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    resolved = settings(config, args)
    if not resolved.enabled or flag(args, "no_hmi", False):
        return []
    from softplc.adapters.hmi.server import HmiServer

    return [HmiServer(config, resolved)]


def off(config: PlantConfig, args: argparse.Namespace | None) -> str | None:
    if flag(args, "no_hmi", False):
        return "the web HMI (--no-hmi)"
    if not settings(config, args).enabled:
        return f"the web HMI (servers.hmi.enabled: false in {config.path.name}): set enabled: true to serve it"
    return None


MANIFEST = Manifest(
    name="hmi",
    title="the web HMI",
    order=80,  # last: a browser sees every other adapter's pages, commands and figures
    sections=SECTIONS,
    add_arguments=add_arguments,
    build=build,
    server=True,
    off=off,
    figures={
        "clients": gauge("softplc_hmi_clients", "HMI live connections (browser tabs) open"),
        "sessions": gauge("softplc_hmi_sessions", "HMI login sessions"),
        "clients_dropped": counter("softplc_hmi_clients_dropped_total", "HMI live clients dropped for being too slow or silent"),
        "updates_encoded": counter("softplc_hmi_updates_encoded_total", "HMI live messages encoded (each sent to every client of its group)"),
    },
)
