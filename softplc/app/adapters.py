"""Which adapters `softplc run` starts around the core: every manifest's, from the configuration and flags.

Adapters are found by their manifests (`softplc.config.manifest.manifests()`: each folder of
`softplc/adapters/` with a `manifest.py`); each one contributes its flags of `run`
(`add_run_arguments`), builds itself from the configuration (`build_adapters`) and says why it
is off (`servers_off`). Nothing here names an adapter.

Every protocol server is on by default, on loopback and its default port; `run` says which
ones are off and how to turn them on. Under `--sim` a server whose port is not given on the
command line binds port 0 (any free port, printed in its `serving:` line), so a simulation
never collides with the plant running beside it (`softplc.config.manifest.simulation_port`).
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.config.manifest import flag, manifests, simulation_port

if TYPE_CHECKING:
    from softplc.config import PlantConfig
    from softplc.core.plant import Adapter

__all__ = ["add_run_arguments", "build_adapters", "servers_off", "simulation_port"]


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `softplc run` that belong to adapters, a group each."""
    group = parser.add_argument_group("servers")
    group.add_argument("--no-servers", action="store_true", help="start no protocol server (scan only)")
    for manifest in manifests():
        if manifest.add_arguments is not None:
            manifest.add_arguments(parser)


def build_adapters(config: PlantConfig, args: argparse.Namespace | None = None) -> list[Adapter]:
    """The adapters to start for this plant, in start order, honouring command-line overrides in `args`.

    Raises one ConfigError with the problems of every adapter's section, not just the first's.
    """
    from softplc.config.yamlsource import ConfigError, Problem

    no_servers = bool(flag(args, "no_servers", False))
    adapters: list[Adapter] = []
    problems: list[Problem] = []
    for manifest in manifests():
        if manifest.server and no_servers:
            continue
        try:
            adapters.extend(manifest.build(config, args))
        except ConfigError as error:
            problems.extend(error.problems)
    if problems:
        raise ConfigError(problems)
    return adapters


def servers_off(config: PlantConfig, args: argparse.Namespace | None = None) -> list[str]:
    """The protocol servers this run does not start, each with why and how to turn it on."""
    if flag(args, "no_servers", False):
        titles = [manifest.title for manifest in manifests() if manifest.server and manifest.off is not None]
        return [f"{', '.join(titles[:-1])} and {titles[-1]} (--no-servers): run without it to serve them"]
    return [note for manifest in manifests() if manifest.off is not None and (note := manifest.off(config, args))]
