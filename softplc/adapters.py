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


def build_adapters(config: PlantConfig, args: argparse.Namespace | None = None) -> list[Adapter]:
    """The adapters to start for this plant, honouring command-line overrides in `args`."""
    adapters: list[Adapter] = []
    if args is not None and getattr(args, "no_servers", False):
        return adapters
    return adapters
