"""The owners of tagdb.yaml's sections, in one registry that `check`, `run` and `schema` read.

The core's own sections (plant, tags, templates, tasks) are checked in `softplc.config`.
Every other part of the file belongs to a module that declares it with a `SECTION` (below):
where its mapping lives (`("servers", "modbus")`, `("fleet",)`), its JSON Schema, the keys it
adds to every tag, template and program (their values land in `TagDef.options[key]` and
`ProgramConfig.options[key]`), and a check for
what a schema cannot say. To add a section, define `SECTION` in a light module and list the
module in SECTION_MODULES (see docs/runtime.md, "Adding a configuration section").
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from softplc.config import PlantConfig
    from softplc.yamlsource import Problem

# Modules that own a section (each defines SECTION), in the order their problems are reported.
# They are imported whenever a configuration is loaded, so they must not import asyncua,
# pymodbus, numpy and the like at module level (tests/test_config_sections.py checks it).
SECTION_MODULES: tuple[str, ...] = (
    "softplc.runtime_section",
    "softplc.opcua.section",
    "softplc.modbus.section",
    "softplc.fleet.section",
)


@dataclass(frozen=True)
class Section:
    """One owner's part of the configuration file."""

    path: tuple[str, ...]  # where its mapping lives, e.g. ("servers", "modbus")
    schema: dict[str, Any]  # the JSON Schema of that mapping
    # Keys the owner adds to every tag (plain or in a template): key → JSON Schema of its value.
    tag_keys: Mapping[str, dict[str, Any]] = field(default_factory=dict)
    # Keys the owner adds to every template: the value applies to each tag of the template
    # (a tag's own key, if it has one, wins; two mappings are merged key by key).
    template_keys: Mapping[str, dict[str, Any]] = field(default_factory=dict)
    # Keys the owner adds to every program of a task (values land in ProgramConfig.options[key]).
    program_keys: Mapping[str, dict[str, Any]] = field(default_factory=dict)
    # What the schema cannot say (a bad duration's text, overlapping addresses, a missing
    # file), as located problems. Runs only on a configuration whose core is free of problems.
    problems: Callable[[PlantConfig], list[Problem]] | None = None


class RegistryError(RuntimeError):
    """Two owners claim the same section or key (a programming error, not the user's)."""


@functools.cache
def registered() -> tuple[Section, ...]:
    """Every owner's SECTION, in SECTION_MODULES order."""
    return check_registry(tuple(importlib.import_module(name).SECTION for name in SECTION_MODULES))


def check_registry(sections: tuple[Section, ...]) -> tuple[Section, ...]:
    """`sections`, after making sure no path, tag key or template key is claimed twice."""
    for what, keys in (("section", [s.path for s in sections]), ("tag key", [k for s in sections for k in s.tag_keys]),
                       ("template key", [k for s in sections for k in s.template_keys]),
                       ("program key", [k for s in sections for k in s.program_keys])):
        doubles = sorted({str(key) for key in keys if keys.count(key) > 1})
        if doubles:
            raise RegistryError(f"{what} claimed by two owners: {', '.join(doubles)}")
    paths = [s.path for s in sections]
    for path in paths:
        if any(other != path and other == path[: len(other)] for other in paths):
            raise RegistryError(f"section {'.'.join(path)} lies inside another owner's section")
    return sections


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
