"""The `mqtt:` section's manifest (softplc.config.manifest): the broker settings every MQTT user shares."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.config.manifest import Manifest
from softplc.config.schema import Section
from softplc.protocols.mqtt_settings import SCHEMA, problems

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    """The embedded broker when `mqtt: {embedded: true}` (a demo); else nothing: each MQTT user connects by itself."""
    if not isinstance(config.raw.get("mqtt"), dict) or not config.raw["mqtt"].get("embedded"):
        return []
    from softplc.adapters.mqtt.broker import EmbeddedBroker
    from softplc.protocols.mqtt_settings import MqttSettings

    return [EmbeddedBroker(MqttSettings.from_config(config))]


MANIFEST = Manifest(
    name="mqtt",
    title="MQTT",
    order=25,  # before its users
    sections=(Section(path=("mqtt",), schema=SCHEMA, problems=problems),),
    build=build,
)
