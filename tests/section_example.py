"""A section owner written the way a new adapter writes one: `notebook:` at the top level, a
`notebook:` key on tags and templates, and a `record:` key on programs. tests/config/test_config_sections.py
plugs it into the registry as a manifest's section (softplc/config/manifest.py)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.config.schema import DURATION, Section
from softplc.core.datatypes import DataType
from softplc.core.tags import Access, TagDef
from softplc.util.durations import check_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {"database": {"type": "string"}, "interval": DURATION},
    "additionalProperties": False,
}

TAG_KEY: dict[str, Any] = {
    "type": "object",
    "properties": {"deadband": {"type": "number", "minimum": 0}, "enabled": {"type": "boolean"}},
    "additionalProperties": False,
}


def problems(config: PlantConfig) -> list[Problem]:
    found = []
    section = config.section("notebook")
    if section is not None and "interval" in section:
        _, message = check_duration(section["interval"], "interval")
        if message:
            found.append(config.problem(("notebook", "interval"), message))
    for tag in config.tags:
        options = tag.options.get("notebook")
        if isinstance(options, dict) and "deadband" in options and not tag.type.is_numeric:
            found.append(config.problem((*config.option_path(tag.name, "notebook"), "deadband"),
                                        f"a deadband needs a numeric tag, and '{tag.name}' is {tag.type.value}"))
    return found


def tags(config: PlantConfig) -> list[TagDef]:
    """A tag the owner adds to the runtime, like the alarm summary tags."""
    if config.section("notebook") is None:
        return []
    return [TagDef("_sys.notebook.rows", DataType.UINT32, 0, description="rows recorded", access=Access.RO, runtime_only=True)]


def alarms(config: PlantConfig) -> list[tuple[tuple[str | int, ...], dict[str, Any]]]:
    """An alarm the owner adds, like a link's 'down' alarm: on its own tag, located at its section."""
    if config.section("notebook") is None:
        return []
    return [(("notebook",), {"name": "notebook_full", "limit": {"tag": "_sys.notebook.rows", "hi": 1000}, "priority": "low"})]


SECTION = Section(
    path=("notebook",),
    schema=SCHEMA,
    tag_keys={"notebook": TAG_KEY},
    template_keys={"notebook": TAG_KEY},
    program_keys={"record": {"type": "boolean"}},
    problems=problems,
    tags=tags,
    alarms=alarms,
)
