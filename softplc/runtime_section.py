"""The `runtime:` section of tagdb.yaml: where the plant keeps its state, when a scan is stuck."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.durations import parse_duration
from softplc.schema import DURATION
from softplc.sections import Section

if TYPE_CHECKING:
    from softplc.config import PlantConfig
    from softplc.yamlsource import Problem

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
    value = section["stall_after"]
    try:
        seconds = parse_duration(value)
    except (TypeError, ValueError):
        return [config.problem(("runtime", "stall_after"), f"bad stall_after {value!r}: write a duration such as 10ms, 100ms or 1s")]
    if seconds <= 0:
        return [config.problem(("runtime", "stall_after"), f"bad stall_after {value!r}: must be greater than zero")]
    return []


SECTION = Section(path=("runtime",), schema=SCHEMA, problems=problems)
