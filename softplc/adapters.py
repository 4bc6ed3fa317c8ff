"""Which adapters `softplc run` starts around the core, from the `servers:` section and flags.

Each adapter module contributes its command-line flags to `run` (`add_run_arguments`) and
builds itself from the configuration (`build_adapters`). The core never imports this module.
"""

from __future__ import annotations

import argparse

from softplc.config import PlantConfig
from softplc.runtime import Adapter


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `softplc run` that belong to adapters."""
    group = parser.add_argument_group("servers")
    group.add_argument("--no-servers", action="store_true", help="start no protocol server (scan only)")
    # Modbus TCP (softplc.modbus)
    group.add_argument("--modbus-host", metavar="HOST", help="Modbus TCP bind address (default servers.modbus.host, 127.0.0.1)")
    group.add_argument("--modbus-port", type=int, metavar="PORT", help="Modbus TCP port (default servers.modbus.port, 5020; 0 = any free port)")
    group.add_argument("--no-modbus", action="store_true", help="do not start the Modbus TCP server")


def build_adapters(config: PlantConfig, args: argparse.Namespace | None = None) -> list[Adapter]:
    """The adapters to start for this plant, honouring command-line overrides in `args`."""
    adapters: list[Adapter] = []
    if args is not None and getattr(args, "no_servers", False):
        return adapters
    adapters.extend(_modbus(config, args))
    return adapters


def _modbus(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.modbus.settings import ModbusSettings

    settings = ModbusSettings.from_servers(config.servers).override(
        host=getattr(args, "modbus_host", None),
        port=getattr(args, "modbus_port", None),
        disable=bool(getattr(args, "no_modbus", False)),
    )
    if not settings.enabled:
        return []
    from softplc.modbus.server import ModbusAdapter

    return [ModbusAdapter(config, settings)]
