"""The VDA 5050 master control's manifest (softplc.config.manifest): its section, flag, builder, commands and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.vda5050.section import SECTION
from softplc.config.manifest import Manifest, counter, flag, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("VDA 5050")
    group.add_argument("--no-vda5050", action="store_true", help="do not drive the VDA 5050 vehicles of the vda5050: section")


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.vda5050.settings import VdaSettings

    if not VdaSettings.configured(config) or flag(args, "no_vda5050", False):
        return []
    from softplc.adapters.vda5050.adapter import VdaMaster
    from softplc.protocols.mqtt_settings import MqttSettings
    from softplc.robotics.layout import fleet_files
    from softplc.robotics.roadmap import load_roadmap
    from softplc.robotics.robots import load_robots

    settings = VdaSettings.from_config(config)
    return [VdaMaster(settings, MqttSettings.from_config(config), load_robots(fleet_files(config)["robots"]), load_roadmap(settings.roadmap))]


MANIFEST = Manifest(
    name="vda5050",
    title="VDA 5050 master control",
    order=35,  # after the fleet (30), whose robot tags it shares; after the embedded broker (mqtt, 25)
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    commands=("softplc.clients.vda5050.cli",),
    figures={
        "vehicles_alive": gauge("softplc_vda5050_vehicles_alive", "VDA 5050 vehicles whose state is fresh"),
        "messages_sent": counter("softplc_vda5050_messages_sent_total", "orders and instant actions published"),
        "schema_violations": counter("softplc_vda5050_schema_violations_total", "messages not sent: they failed their JSON Schema"),
        "bad_messages": counter("softplc_vda5050_bad_messages_total", "vehicle messages dropped: not JSON, not valid, wrong vehicle"),
        "order_resends": gauge("softplc_vda5050_order_resends", "orders re-sent identically for want of an acknowledgement (current trips)"),
        "reservation_conflicts": counter("softplc_vda5050_reservation_conflicts_total", "a vehicle found standing on a node another held"),
        "deadlocks_broken": counter("softplc_vda5050_deadlocks_broken_total", "reservation deadlocks broken by a re-route"),
    },
)
