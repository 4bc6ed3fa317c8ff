"""The links' manifest (softplc.config.manifest): the `links:` section, the `--no-links` flag, the builder and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.links.section import SECTION_OWNER
from softplc.config.manifest import Manifest, counter, flag, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("links to other controllers")
    group.add_argument("--no-links", action="store_true", help="do not connect the links: section's remote controllers")


def _links(config: PlantConfig) -> list:  # type: ignore[type-arg]
    from softplc.adapters.links.settings import read_links

    return [link for link in read_links(config).links.values() if link.enabled]


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    if config.section("links") is None or off(config, args) is not None:
        return []
    links = _links(config)
    if not links:
        return []
    from softplc.adapters.links.adapter import LinksAdapter

    return [LinksAdapter(config, links)]


def off(config: PlantConfig, args: argparse.Namespace | None) -> str | None:
    if config.section("links") is None:
        return None
    if flag(args, "no_links", False):
        return "links (--no-links)"
    if flag(args, "sim", False):
        # A simulated clock jumps ahead of the network: every link would look silent for periods.
        return "links (a simulated clock runs ahead of the remote controllers: run without --sim to connect them)"
    return None


MANIFEST = Manifest(
    name="links",
    title="links",
    order=45,  # before the servers: a client's first read already finds the bound tags' quality
    sections=(SECTION_OWNER,),
    add_arguments=add_arguments,
    build=build,
    off=off,
    figures={
        "connected": gauge("softplc_link_connected", "1 while the link's remote controller answers", "link"),
        "tags": gauge("softplc_link_tags", "Tags read from the link's remote, by the quality they show", "link", "quality"),
        "requests": counter("softplc_link_requests_total", "Requests sent to the link's remote (reads, writes, heartbeats)", "link"),
        "reconnects": counter("softplc_link_reconnects_total", "Connections made after the link's first", "link"),
        "writes": counter("softplc_link_writes_total", "Values sent to the link's remote, by result (ok, refused, failed)", "link", "result"),
        "round_trip": gauge("softplc_link_round_trip_seconds", "The last poll's (Modbus) or heartbeat's (OPC UA) round trip", "link"),
    },
)
