"""The alarms' part of tagdb.yaml: the `alarms:` section (docs/alarms.md), and the summary tags it adds.

A plant with an `alarms:` section gets the `_sys.alarms.*` summary tags (counts, highest
priority, an acknowledge-all command) for Modbus and legacy SCADA, like the system tags.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from softplc.adapters.alarms.schema import alarms_schema
from softplc.adapters.alarms.settings import alarm_problems
from softplc.adapters.alarms.summary import summary_tag_definitions
from softplc.config.schema import DURATION, Section

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.tags import TagDef


def summary_tags(config: PlantConfig) -> list[TagDef]:
    return summary_tag_definitions() if isinstance(config.section("alarms"), dict) else []


SECTION = Section(
    path=("alarms",),
    schema=alarms_schema(DURATION),
    problems=alarm_problems,
    tags=summary_tags,
)
