"""The alarms' manifest (softplc.config.manifest): its section, builder and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.alarms.section import SECTION
from softplc.config.manifest import Manifest, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.alarms.settings import AlarmSettings, configured

    if not configured(config):
        return []
    from softplc.adapters.alarms.adapter import AlarmsAdapter

    return [AlarmsAdapter(AlarmSettings.from_config(config))]  # ConfigError: located problems of alarms:


MANIFEST = Manifest(
    name="alarms",
    title="alarms",
    order=20,  # before the servers: the OPC UA server lists the alarms as conditions when it starts
    sections=(SECTION,),
    build=build,
    figures={
        "active": gauge("softplc_alarms_active", "Alarms active (unacknowledged or acknowledged), not shelved or suppressed"),
        "unacknowledged": gauge("softplc_alarms_unacknowledged", "Alarms waiting for an acknowledgement"),
        "shelved": gauge("softplc_alarms_shelved", "Alarms shelved"),
    },
)
