"""The robot fleet's manifest (softplc.config.manifest): its section, flag, builder, commands and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.fleet.section import SECTION
from softplc.config.manifest import Manifest, flag, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("robots")
    group.add_argument("--no-fleet", action="store_true", help="do not drive the robots of the fleet: section")


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.fleet.settings import FleetSettings

    if not FleetSettings.configured(config) or flag(args, "no_fleet", False):
        return []
    if not FleetSettings.from_config(config).enabled:
        return []
    from softplc.adapters.fleet.adapter import FleetAdapter

    return [FleetAdapter.from_config(config)]


MANIFEST = Manifest(
    name="fleet",
    title="robot fleet",
    order=30,
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    commands=("softplc.adapters.fleet.cli",),
    figures={"robots": gauge("softplc_robots", "Robots by navigation state (offline: a remote robot not reporting)", "navstate")},
)
