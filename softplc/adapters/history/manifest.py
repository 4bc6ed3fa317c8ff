"""The historian's manifest (softplc.config.manifest): its section, flag, builder, commands and figures."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.history.section import SECTION
from softplc.config.manifest import Manifest, counter, flag, gauge

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("history")
    group.add_argument("--no-history", action="store_true", help="record no history (the history: section)")


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.adapters.history.section import tag_rules
    from softplc.adapters.history.settings import HistorySettings
    from softplc.config.system_tags import runtime_tag_definitions

    rules = tag_rules(config)
    if not HistorySettings.configured(config) and not rules:
        return []
    definitions = [*config.tags, *runtime_tag_definitions(config)]
    settings = HistorySettings.from_config(config, rules)  # checked by its section owner (section.py)
    if not settings.enabled or flag(args, "no_history", False):
        return []
    if flag(args, "sim", False) and not settings.sim:
        return []
    from softplc.adapters.history.recorder import HistoryRecorder

    policies = settings.policies(definitions)
    types = {d.name: (d.type.value, d.unit) for d in definitions if d.name in policies}
    return [HistoryRecorder(settings, config.name, policies, types)]


MANIFEST = Manifest(
    name="history",
    title="historian",
    order=40,  # before the OPC UA server: it asks which tags are historized as it builds its nodes
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
    commands=("softplc.adapters.history.cli",),
    figures={
        "tags": gauge("softplc_history_tags", "Tags the historian records"),
        "rows_written": counter("softplc_history_rows_written_total", "History rows committed to the store"),
        "queue": gauge("softplc_history_queue_rows", "History rows waiting for the writer (the queue depth)"),
        "rows_dropped": counter("softplc_history_rows_dropped_total", "History rows dropped because the queue was full (the store was down)"),
        "errors": counter("softplc_history_write_errors_total", "Failed history commits (retried)"),
    },
)
