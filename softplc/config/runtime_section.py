"""The `runtime:` section of tagdb.yaml: where the plant keeps its state, when a scan is stuck."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.config.schema import DURATION, Section
from softplc.util.durations import check_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "state_dir": {"type": "string", "description": "Where retained values, certificates etc. live (default .softplc next to this file)."},
        "stall_after": DURATION,
    },
    "additionalProperties": False,
}


def problems(config: PlantConfig) -> list[Problem]:
    """A stall_after that is not a positive duration."""
    section = config.section("runtime")
    if section is None or "stall_after" not in section:
        return []
    _, message = check_duration(section["stall_after"], "stall_after")
    return [config.problem(("runtime", "stall_after"), message)] if message else []


SECTION = Section(path=("runtime",), schema=SCHEMA, problems=problems)
