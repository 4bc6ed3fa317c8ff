"""The owners of tagdb.yaml's sections, in one registry that `check`, `run` and `schema` read.

The core's own sections (plant, tags, templates, tasks) are checked in `softplc.config`. Every
other part of the file belongs to a module that declares it with a `SECTION` (a
`softplc.config.schema.Section`): where its mapping lives (`("servers", "modbus")`, `("fleet",)`), its
JSON Schema, the keys it adds to every tag, template and program (their values land in
`TagDef.options[key]` and `ProgramConfig.options[key]`), and a check for what a schema cannot
say. To add a section, define `SECTION` in a light module and list the module in
SECTION_MODULES (docs/runtime.md, "Adding a configuration section"). Owners import `Section`
from `softplc.config.schema` and `PlantConfig` from `softplc.config.plant`, never this module or the
loader, so the registry stays free of import cycles (tests/app/test_imports.py).
"""

from __future__ import annotations

import functools
import importlib
from typing import TYPE_CHECKING, Any

from softplc.config.schema import Section, build_schema, check_registry, strict_durations

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.tags import TagDef
    from softplc.config.yamlsource import Problem

# Modules that own a section (each defines SECTION, or SECTIONS for several), in the order their
# problems are reported.
# They are imported whenever a configuration is loaded, so they must not import asyncua,
# pymodbus, numpy and the like at module level (tests/config/test_config_sections.py checks it).
SECTION_MODULES: tuple[str, ...] = (
    "softplc.engine.section",
    "softplc.adapters.opcua.section",
    "softplc.adapters.modbus.section",
    "softplc.adapters.fleet.section",
    "softplc.adapters.history.section",
    "softplc.adapters.alarms.section",
    "softplc.adapters.hmi.section",
    "softplc.adapters.audit.section",
)


@functools.cache
def registered() -> tuple[Section, ...]:
    """Every owner's SECTION, in SECTION_MODULES order."""
    owned: list[Section] = []
    for name in SECTION_MODULES:
        module = importlib.import_module(name)
        owned.extend(getattr(module, "SECTIONS", None) or (module.SECTION,))  # an owner of two parts lists both
    return check_registry(tuple(owned))


def tag_keys(sections: tuple[Section, ...] | None = None) -> dict[str, dict[str, Any]]:
    """Every key the owners add to tags, with its schema."""
    return {key: schema for section in (registered() if sections is None else sections) for key, schema in section.tag_keys.items()}


def template_keys(sections: tuple[Section, ...] | None = None) -> dict[str, dict[str, Any]]:
    """Every key the owners add to templates, with its schema."""
    return {key: schema for section in (registered() if sections is None else sections) for key, schema in section.template_keys.items()}


def program_keys(sections: tuple[Section, ...] | None = None) -> dict[str, dict[str, Any]]:
    """Every key the owners add to programs, with its schema."""
    return {key: schema for section in (registered() if sections is None else sections) for key, schema in section.program_keys.items()}


def section_problems(config: PlantConfig, sections: tuple[Section, ...] | None = None) -> list[Problem]:
    """Every owner's problems with this (core-valid) configuration, in registry order."""
    problems: list[Problem] = []
    for section in registered() if sections is None else sections:
        if section.problems is not None:
            problems.extend(section.problems(config))
    return problems


def contributed_tags(config: PlantConfig, sections: tuple[Section, ...] | None = None) -> list[TagDef]:
    """The tags the owners add to the runtime of this (valid) configuration, in registry order."""
    tags: list[TagDef] = []
    for section in registered() if sections is None else sections:
        if section.tags is not None:
            tags.extend(section.tags(config))
    return tags


@functools.cache
def config_schema() -> dict[str, Any]:
    """The whole file's schema: the core's sections plus every registered owner's."""
    return build_schema(registered())


def editor_schema() -> dict[str, Any]:
    """The schema `softplc schema` prints: config_schema() with durations checked for their form too."""
    return strict_durations(config_schema())
