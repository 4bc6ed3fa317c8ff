"""The Sparkplug B edge node's manifest (softplc.config.manifest): its section, flag, builder and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.sparkplug.section import SECTION
from softplc.config.manifest import Manifest, counter, flag, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("Sparkplug B")
    group.add_argument("--no-sparkplug", action="store_true", help="do not start the Sparkplug B edge node (the sparkplug: section)")


def off(config: PlantConfig, args: argparse.Namespace | None) -> str | None:
    section = config.section("sparkplug")
    if section is None:
        return None
    if flag(args, "no_sparkplug", False):
        return "Sparkplug B edge node (--no-sparkplug)"
    if section.get("enabled") is False:
        return f"Sparkplug B edge node (sparkplug.enabled: false in {config.path.name})"
    if flag(args, "sim", False) and not section.get("sim", False):
        return "Sparkplug B edge node (a --sim run stays off the plant's SCADA; sparkplug.sim: true publishes it)"
    return None


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    if config.section("sparkplug") is None or off(config, args) is not None:
        return []
    from softplc.adapters.sparkplug.edge_node import EdgeNode
    from softplc.adapters.sparkplug.settings import SparkplugSettings
    from softplc.protocols.mqtt_settings import MqttSettings

    return [EdgeNode(SparkplugSettings.from_config(config), MqttSettings.from_config(config))]


MANIFEST = Manifest(
    name="sparkplug",
    title="Sparkplug B edge node",
    order=65,  # after the servers, before the metrics and the HMI, which show its state
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    off=off,
    figures={
        "connected": gauge("softplc_sparkplug_connected", "1 while connected to the MQTT broker"),
        "online": gauge("softplc_sparkplug_online", "1 while the edge node is born (publishing)"),
        "births": counter("softplc_sparkplug_births_total", "NBIRTHs published (connects and rebirths)"),
        "messages": counter("softplc_sparkplug_messages_total", "Sparkplug messages published"),
        "metrics": counter("softplc_sparkplug_metrics_total", "Metric values published in data messages"),
        "stored": gauge("softplc_sparkplug_stored_messages", "Data messages in the store, waiting to be forwarded"),
        "dropped": counter("softplc_sparkplug_dropped_total", "Data messages dropped (store full or off)"),
        "commands": counter("softplc_sparkplug_command_metrics_total", "Command metrics (NCMD/DCMD) by result", "result"),
    },
)
