"""Adapter manifests: how an adapter declares itself, and how the runtime finds every adapter.

An adapter is a folder `softplc/adapters/NAME/` whose `manifest.py` defines `MANIFEST`:

    MANIFEST = Manifest(
        name="modbus",
        title="Modbus TCP server",
        order=60,                          # start order: lower starts first and stops last
        sections=(SECTION,),               # its part of tagdb.yaml (softplc.config.schema.Section)
        add_arguments=add_arguments,       # its flags of `softplc run`
        build=build,                       # (config, args) -> the adapters to start, honouring the flags
        server=True,                       # a protocol server: `--no-servers` leaves it out
        off=off,                           # (config, args) -> why it is off and how to turn it on, or None
        commands=("softplc.adapters.modbus.cli",),   # modules adding `softplc` subcommands
        figures={"connections": gauge("softplc_modbus_connections", "...")},  # what its metrics() reports
    )

`manifests()` finds them by scanning the folder: a new adapter touches no central file. A
manifest module is imported whenever a configuration is checked, so it stays light: it imports
its section module and nothing heavy (asyncua, aiohttp, numpy...) at module level; `build`
imports the adapter itself.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import pkgutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.schema import Section
    from softplc.core.plant import Adapter

ADAPTER_PACKAGE = "softplc.adapters"


@dataclass(frozen=True)
class Figure:
    """How one figure an adapter reports is shown on /metrics: metric name, kind, help, label names."""

    name: str
    kind: str  # "gauge" or "counter" (a counter's name ends in _total)
    help: str
    labels: tuple[str, ...] = ()


def gauge(name: str, help: str, *labels: str) -> Figure:
    return Figure(name, "gauge", help, labels)


def counter(name: str, help: str, *labels: str) -> Figure:
    return Figure(name, "counter", help, labels)


Builder = Callable[["PlantConfig", "argparse.Namespace | None"], "list[Adapter]"]


@dataclass(frozen=True)
class Manifest:
    """One adapter's declaration (see the module docstring)."""

    name: str
    title: str
    order: int
    build: Builder
    sections: tuple[Section, ...] = ()
    add_arguments: Callable[[argparse.ArgumentParser], None] | None = None
    server: bool = False
    off: Callable[[PlantConfig, argparse.Namespace | None], str | None] | None = None
    commands: tuple[str, ...] = ()
    figures: Mapping[str, Figure] = field(default_factory=dict)


@functools.cache
def manifests() -> tuple[Manifest, ...]:
    """Every adapter's manifest, in start order (ties by name)."""
    package = importlib.import_module(ADAPTER_PACKAGE)
    found = []
    for module in pkgutil.iter_modules(package.__path__):
        if not module.ispkg:
            continue
        try:
            manifest_module = importlib.import_module(f"{ADAPTER_PACKAGE}.{module.name}.manifest")
        except ModuleNotFoundError as error:
            if error.name == f"{ADAPTER_PACKAGE}.{module.name}.manifest":
                continue  # a support package without a manifest is not an adapter
            raise
        found.append(manifest_module.MANIFEST)
    names = [manifest.name for manifest in found]
    doubles = sorted({name for name in names if names.count(name) > 1})
    if doubles:
        raise RuntimeError(f"two adapters are named {', '.join(doubles)}")
    return tuple(sorted(found, key=lambda manifest: (manifest.order, manifest.name)))


def figure_of(adapter: str, key: str, labelled: bool) -> Figure:
    """How an adapter's figure is shown: its manifest's entry, or a gauge named after the adapter and the figure."""
    import re

    for manifest in manifests():
        if manifest.name == adapter and key in manifest.figures:
            return manifest.figures[key]
    name = re.sub(r"[^a-zA-Z0-9_]", "_", f"softplc_{adapter}_{key}")
    return gauge(name, f"{key} (reported by the {adapter} adapter)", *(("key",) if labelled else ()))


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


def flag(args: argparse.Namespace | None, name: str, default: Any = None) -> Any:
    """A `softplc run` flag's value, or `default` when there are no arguments (a runtime built in code)."""
    return getattr(args, name, default) if args is not None else default
