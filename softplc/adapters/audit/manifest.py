"""The audit trail's manifest (softplc.config.manifest): its section, flag and builder."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.adapters.audit.section import SECTION
from softplc.config.manifest import Manifest, flag

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("audit trail")
    group.add_argument("--no-audit", action="store_true", help="keep no audit trail of writes and commands for this run (the audit: section)")


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    from softplc.storage.audit.settings import AuditSettings

    settings = AuditSettings.from_config(config)  # checked by its section owner (section.py)
    if not settings.enabled or flag(args, "no_audit", False):
        return []
    from softplc.adapters.audit.recorder import AuditRecorder

    return [AuditRecorder(settings, config.name)]


MANIFEST = Manifest(
    name="audit",
    title="audit trail",
    order=10,  # first: it listens before any client can write, and stops last
    sections=(SECTION,),
    add_arguments=add_arguments,
    build=build,
)
