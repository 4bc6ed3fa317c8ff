"""The redundancy adapter's manifest (softplc.config.manifest): its section, flag, builder, commands and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.redundancy.section import SECTION
from softplc.config.manifest import Manifest, counter, flag, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("redundant pair (the redundancy: section)")
    group.add_argument("--redundancy-member", metavar="NAME",
                       help="which member of the pair this runtime is (default $SOFTPLC_REDUNDANCY_MEMBER, else redundancy.member)")


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    if config.section("redundancy") is None:
        return []
    if flag(args, "sim", False):
        return []  # a simulation is never a member of the real plant's pair
    from softplc.adapters.redundancy.adapter import RedundancyAdapter
    from softplc.adapters.redundancy.settings import SettingsError, from_config
    from softplc.config.yamlsource import ConfigError

    try:
        settings = from_config(config, flag(args, "redundancy_member"))
    except SettingsError as error:
        raise ConfigError([config.problem(("redundancy",), str(error))]) from None
    return [RedundancyAdapter(config, settings)]


MANIFEST = Manifest(
    name="redundancy",
    title="redundant pair",
    order=5,  # first: the role is decided before any server accepts a write, and given up last
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    commands=("softplc.clients.redundancy.cli",),
    figures={
        "active": gauge("softplc_redundancy_active", "1 while this runtime is the active member of its pair"),
        "epoch": gauge("softplc_redundancy_epoch", "the epoch of the current active term (etcd revision)"),
        "service_level": gauge("softplc_redundancy_service_level", "the OPC UA ServiceLevel this runtime shows"),
        "failovers": counter("softplc_redundancy_failovers_total", "times this runtime took over from an active"),
        "refused": counter("softplc_redundancy_refused_total", "sync connections and messages refused"),
        "peer_ok": gauge("softplc_redundancy_peer_in_sync", "1 while the peer is there and in sync"),
        "sync_age": gauge("softplc_redundancy_sync_age_seconds", "age of the last state applied (standby) or acknowledged (active)"),
        "sync_lag": gauge("softplc_redundancy_sync_lag_states", "states sent to the standby and not yet acknowledged"),
        "coordinator_ok": gauge("softplc_redundancy_coordinator_up", "1 while etcd answers"),
    },
)
