"""The JSON Schema of `tagdb.yaml`, and the `Section` with which a module declares its part of it.

The core's sections (plant, tags, templates, tasks) are declared here; every other section,
and the keys adapters add to tags, templates and programs, come from their owners, which
`softplc.config.sections` lists (it assembles what `softplc check` uses and `softplc schema` prints).
What a schema cannot say (a binding to a missing tag, an initial value outside its type, a
program class that does not exist) is checked in `softplc.config`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from softplc.core.datatypes import TYPE_NAMES
from softplc.util.durations import DURATION_REGEX

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem
    from softplc.core.tags import TagDef

NAME_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"
NAME_RULE = "ASCII letters, digits and _, not starting with a digit"

DURATION: dict[str, Any] = {
    "description": "A duration: 10ms, 1s, 2min, 250us, or a number of seconds.",
    "type": ["string", "number"],
}

TAG: dict[str, Any] = {
    "description": "A tag: a typed value with quality and timestamp.",
    "type": "object",
    "properties": {
        "type": {"enum": list(TYPE_NAMES), "description": "The tag's data type."},
        "initial": {"type": ["boolean", "number", "string"], "description": "Value at start (default 0, false or '')."},
        "unit": {"type": "string", "description": "Engineering unit, e.g. m, %, items/min."},
        "description": {"type": "string"},
        "access": {"enum": ["rw", "ro"], "description": "ro: read-only for clients (programs may write)."},
        "min": {"type": "number", "description": "Lowest value a write may set."},
        "max": {"type": "number", "description": "Highest value a write may set."},
        "retain": {"type": "boolean", "description": "Keep the value across restarts (stored in SQLite)."},
        "group": {"type": "string", "description": "Folder path for browsing, e.g. Plant/Handshake."},
        "shared_output": {
            "type": "boolean",
            "description": "Several programs may write this tag (a handshake flag one sets and another clears, a counter "
            "each increments); without it a second writing program is an error.",
        },
    },
    "required": ["type"],
    "additionalProperties": False,
}

TAGS: dict[str, Any] = {
    "type": "object",
    "propertyNames": {"pattern": NAME_PATTERN},
    "additionalProperties": TAG,
}

TEMPLATE: dict[str, Any] = {
    "description": "A tag set declared once and instantiated per robot or task: tag NAME becomes INSTANCE_NAME.",
    "type": "object",
    "properties": {
        "description": {"type": "string"},
        "group": {"type": "string", "description": "Folder of the instances, e.g. Robots."},
        "instances": {
            "type": "array",
            "items": {"type": "string", "pattern": NAME_PATTERN},
            "description": "Instance names, e.g. [r01, r02, r03].",
        },
        "count": {"type": "integer", "minimum": 1, "maximum": 9999, "description": "Number of instances PREFIX01..PREFIXnn."},
        "prefix": {"type": "string", "pattern": NAME_PATTERN, "description": "Instance name prefix used with count."},
        "instances_from": {
            "description": "Instance names from the `id` of each item of a YAML list in another file "
            "(e.g. robots/robots.yaml), optionally with initial values taken from the items.",
            "type": ["string", "object"],
            "properties": {
                "file": {"type": "string", "description": "YAML file, relative to this one."},
                "key": {"type": "string", "description": "The top-level key of the list (default: the file's only list)."},
                "initial": {
                    "type": "object",
                    "additionalProperties": {"type": "string"},
                    "description": "TAG: dotted.key of an item, e.g. {xpos: start.x}; items without the key keep the tag's initial.",
                },
            },
            "required": ["file"],
            "additionalProperties": False,
        },
        "tags": TAGS,
        "initial": {
            "type": "object",
            "description": "Per-instance initial values: {INSTANCE: {TAG: value}}.",
            "additionalProperties": {"type": "object", "additionalProperties": {"type": ["boolean", "number", "string"]}},
        },
    },
    "required": ["tags"],
    "additionalProperties": False,
}

PROGRAM: dict[str, Any] = {
    "description": "A program instance: a Program class and the binding of its variables to tags.",
    "type": "object",
    "properties": {
        "name": {"type": "string", "description": "Instance name; may use {INSTANCE} with for_each."},
        "program": {"type": "string", "description": "module:Class or module.Class, or path/to/file.py:Class."},
        "for_each": {"type": "string", "description": "A template name: one instance per template instance."},
        "bind": {
            "type": "object",
            "additionalProperties": {"type": ["string", "array"], "items": {"type": "string"}},
            "description": "Variable → tag name (or list of tag names).",
        },
        "params": {"type": "object", "description": "Constant parameters of the program."},
        "on_fault": {
            "description": "What the program's outputs do in the scan in which it faults (and when it is stopped): hold "
            "(the default: keep their last values), initial (Output tags back to their initial values), or "
            "{safe: {TAG: value}, others: hold|initial}.",
            "type": ["string", "object"],
            "if": {"type": "string"},
            "then": {"enum": ["hold", "initial"]},
            "properties": {
                "safe": {
                    "type": "object",
                    "additionalProperties": {"type": ["boolean", "number", "string"]},
                    "description": "TAG: safe value, for tags the program writes (its Output and InOut variables).",
                },
                "others": {"enum": ["hold", "initial"], "description": "What the outputs not named in safe do (default hold)."},
            },
            "required": ["safe"],
            "additionalProperties": False,
        },
        "restart": {
            "description": "Restart the program by itself after a fault: never (the default) or {delay: 1s, max: 3}.",
            "type": ["string", "object"],
            "if": {"type": "string"},
            "then": {"enum": ["never"]},
            "properties": {
                "delay": DURATION,
                "max": {"type": "integer", "minimum": 0, "description": "Restarts before it stays FAULTED (default 3)."},
            },
            "additionalProperties": False,
        },
        "enabled": {"type": "boolean"},
    },
    "required": ["name", "program"],
    "additionalProperties": False,
}

TASK: dict[str, Any] = {
    "description": "A cyclic task: its programs run every `interval`.",
    "type": "object",
    "properties": {
        "interval": DURATION,
        "priority": {"type": "integer", "minimum": 0, "maximum": 31, "description": "0 is the highest priority."},
        "watchdog": DURATION,
        "programs": {"type": "array", "items": PROGRAM},
    },
    "required": ["interval"],
    "additionalProperties": False,
}


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
    # Tags the owner adds to the runtime, like the system tags (e.g. alarm summary tags under
    # `_sys.`): served over every protocol, listed by `softplc tags`, usable in --until.
    tags: Callable[[PlantConfig], list[TagDef]] | None = None
    # Alarms the owner adds (e.g. "link plc2 is down" on its `_sys.links.` tag), each as (the
    # path in the file it stems from, its definition in the `alarms:` syntax): the alarms adapter
    # evaluates them beside the user's, and a problem with one (a name taken twice) points there.
    alarms: Callable[[PlantConfig], list[tuple[tuple[str | int, ...], dict[str, Any]]]] | None = None


class RegistryError(RuntimeError):
    """Two owners claim the same section or key (a programming error, not the user's)."""


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


# Containers of owners' sections that are not sections themselves (e.g. servers: opcua, modbus).
CONTAINERS: dict[str, str] = {"servers": "Protocol servers: each one's settings under its name."}

CORE_SECTIONS = ("version", "plant", "templates", "tags", "tasks")


def build_schema(sections: tuple[Section, ...]) -> dict[str, Any]:
    """The file's schema with these owners' sections and tag, template and program keys."""
    check_registry(sections)
    # Copies along the changed paths only: strict_durations() finds DURATION by identity.
    tag = {**TAG, "properties": {**TAG["properties"], **_added(TAG, [s.tag_keys for s in sections])}}
    tags = {**TAGS, "additionalProperties": tag}
    template = {**TEMPLATE, "properties": {**TEMPLATE["properties"], "tags": tags, **_added(TEMPLATE, [s.template_keys for s in sections])}}
    program = {**PROGRAM, "properties": {**PROGRAM["properties"], **_added(PROGRAM, [s.program_keys for s in sections])}}
    task = {**TASK, "properties": {**TASK["properties"], "programs": {**TASK["properties"]["programs"], "items": program}}}
    properties: dict[str, Any] = {
        "version": {"const": 1, "description": "Format version; 1."},
        "plant": {
            "type": "object",
            "properties": {"name": {"type": "string"}, "description": {"type": "string"}},
            "additionalProperties": False,
        },
        "templates": {"type": "object", "propertyNames": {"pattern": NAME_PATTERN}, "additionalProperties": template},
        "tags": tags,
        "tasks": {"type": "object", "propertyNames": {"pattern": NAME_PATTERN}, "additionalProperties": task},
    }
    for section in sections:
        if section.path[0] in CORE_SECTIONS or section.path in [(name,) for name in CONTAINERS]:
            raise RegistryError(f"section {'.'.join(section.path)} belongs to the core")
        parent = properties
        for key in section.path[:-1]:
            container = parent.setdefault(key, {"description": CONTAINERS.get(key, ""), "type": "object", "properties": {}, "additionalProperties": False})
            parent = container["properties"]
        parent[section.path[-1]] = section.schema
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://softplc.dev/schema/tagdb.json",
        "title": "softplc plant configuration (tagdb.yaml)",
        "type": "object",
        "properties": properties,
        "additionalProperties": False,
    }


def _added(core: dict[str, Any], owned: list[Mapping[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """Owners' keys for a core mapping; a key the core already has is a programming error."""
    keys = {key: schema for mapping in owned for key, schema in mapping.items()}
    clashes = sorted(set(keys) & set(core["properties"]))
    if clashes:
        raise RegistryError(f"key claimed by an owner but belonging to the core: {', '.join(clashes)}")
    return keys


# For editors: durations are also checked for their form (the runtime's own check says more:
# `softplc check` reports "bad interval '10 parsecs': write a duration such as 10ms...").
STRICT_DURATION: dict[str, Any] = {
    "description": DURATION["description"],
    "anyOf": [
        {"type": "string", "pattern": DURATION_REGEX},
        {"type": "number", "exclusiveMinimum": 0},
    ],
}


def strict_durations(schema: dict[str, Any]) -> dict[str, Any]:
    """`schema` with durations checked for their form too (what `softplc schema` prints)."""

    def strict(node: Any) -> Any:
        if node is DURATION:
            return STRICT_DURATION
        if isinstance(node, dict):
            return {key: strict(value) for key, value in node.items()}
        if isinstance(node, list):
            return [strict(item) for item in node]
        return node

    return strict(schema)
