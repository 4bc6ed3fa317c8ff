"""The owners of tagdb.yaml's sections, in one registry that `check`, `run` and `schema` read.

The core's own sections (plant, tags, templates, tasks) are checked in `softplc.config`, and the
`runtime:` section by `softplc.config.runtime_section`. Every other part of the file belongs to
an adapter, whose manifest lists its `Section`s (softplc/config/manifest.py): where its mapping
lives (`("servers", "modbus")`, `("fleet",)`), its JSON Schema, the keys it adds to every tag,
template and program (their values land in `TagDef.options[key]` and
`ProgramConfig.options[key]`), and a check for what a schema cannot say. Adapters are found by
scanning `softplc/adapters/` (docs/architecture.md, "Adding an adapter"). Owners import
`Section` from `softplc.config.schema` and `PlantConfig` from `softplc.config.plant`, never this
module or the loader, so the registry stays free of import cycles (tests/app/test_imports.py).
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

from softplc.config.manifest import manifests
from softplc.config.runtime_section import SECTION as RUNTIME_SECTION
from softplc.config.schema import Section, build_schema, check_registry, strict_durations

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem
    from softplc.core.tags import TagDef

@functools.cache
def registered() -> tuple[Section, ...]:
    """Every owner's section: the runtime's, then each adapter's in start order (the order problems are reported in)."""
    return check_registry((RUNTIME_SECTION, *(section for manifest in manifests() for section in manifest.sections)))


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


def contributed_alarms(config: PlantConfig, sections: tuple[Section, ...] | None = None) -> list[tuple[tuple[str | int, ...], dict[str, Any]]]:
    """The alarms the owners add to this (valid) configuration, each with where it stems from, in registry order."""
    alarms: list[tuple[tuple[str | int, ...], dict[str, Any]]] = []
    for section in registered() if sections is None else sections:
        if section.alarms is not None:
            alarms.extend(section.alarms(config))
    return alarms
