"""The `sparkplug:` section: its schema, its checks, its `_sys.sparkplug.*` tags and its alarms.

Imported whenever a configuration is loaded: nothing heavy here (no MQTT, no protobuf).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.adapters.sparkplug import settings
from softplc.config.schema import DURATION, Section
from softplc.core.datatypes import DataType
from softplc.core.roles import ROLE_NAMES
from softplc.core.tags import Access, TagDef

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

PREFIX = settings.OWN_PREFIX
GROUP = "_sys/sparkplug"

_ID = {"type": "string", "minLength": 1}
_ROLE = {"enum": list(ROLE_NAMES), "description": "The role DCMD writes have: viewer (none may write), operator (rw tags), engineer (ro tags too)."}

SCHEMA: dict[str, Any] = {
    "description": "Publish the plant as a Sparkplug B edge node over MQTT (the mqtt: section's broker): docs/sparkplug.md.",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: configured but not started (default true)."},
        "group_id": {**_ID, "description": "The Sparkplug group id (topic spBv1.0/GROUP/...)."},
        "edge_node_id": {**_ID, "description": "The edge node id (default: the plant's name)."},
        "primary_host": {**_ID, "description": "Primary host application id: births wait for spBv1.0/STATE/ID online; data is stored while it is offline."},
        "devices": {
            "type": "array",
            "description": "Which tags as which devices (default: a device per template instance and 'plant' for the rest).",
            "items": {
                "type": "object",
                "properties": {
                    "id": {**_ID, "description": "The device id; for a template, a pattern with {instance} (default {instance})."},
                    "template": {"type": "string", "description": "One device per instance of this template, metrics named by its tags."},
                    "tags": {"anyOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}, "minItems": 1}],
                             "description": "Glob patterns of tag names (metrics named by the tags)."},
                    "role": _ROLE,
                },
                "additionalProperties": False,
            },
        },
        "aliases": {"type": "boolean", "description": "Send metric aliases after the births (default true)."},
        "properties": {"type": "boolean", "description": "Send unit, range, description and read-only in births (default true)."},
        "commands": {
            "type": "object",
            "properties": {
                "role": _ROLE,
                "user": {"type": "string", "description": "The user DCMD writes are audited as (default: the primary host's id)."},
                "clock_tolerance": {**DURATION, "description": "How far a command's timestamp may lie before the birth (default 2s)."},
            },
            "additionalProperties": False,
        },
        "store": {
            "type": "object",
            "description": "Store and forward: data kept on disk while it cannot be delivered, forwarded as historical.",
            "properties": {
                "enabled": {"type": "boolean"},
                "max_size": {"type": ["string", "integer"], "description": "At most this much on disk, oldest dropped first (default 10MB)."},
            },
            "additionalProperties": False,
        },
        "sim": {"type": "boolean", "description": "Also publish under softplc run --sim (default false: a simulation stays off the plant's SCADA)."},
    },
    "required": ["group_id"],
    "additionalProperties": False,
}

# name → (type, initial, description)
STATUS_TAGS: dict[str, tuple[DataType, Any, str]] = {
    "running": (DataType.BOOL, False, "the edge node is started (false while softplc runs without it, e.g. under --sim)"),
    "state": (DataType.STRING, "off", "off, connecting, waiting for primary host, online"),
    "connected": (DataType.BOOL, False, "connected to the MQTT broker"),
    "primary_host_online": (DataType.BOOL, False, "the primary host's STATE says online (true when none is configured)"),
    "bdseq": (DataType.UINT16, 0, "bdSeq of the current MQTT session"),
    "births": (DataType.UINT32, 0, "NBIRTHs published (connects and rebirths)"),
    "messages": (DataType.UINT32, 0, "Sparkplug messages published"),
    "metrics": (DataType.UINT32, 0, "metric values published in data messages"),
    "stored": (DataType.UINT32, 0, "data messages stored, waiting to be forwarded"),
    "dropped": (DataType.UINT32, 0, "data messages dropped (store full or off)"),
    "commands": (DataType.UINT32, 0, "command metrics applied (NCMD/DCMD)"),
    "refused": (DataType.UINT32, 0, "command metrics or messages refused"),
    "last_refusal": (DataType.STRING, "", "why the last command was refused"),
}


def tags(config: PlantConfig) -> list[TagDef]:
    """The `_sys.sparkplug.*` status tags (written by the edge node only)."""
    if not isinstance(config.raw.get(settings.SECTION), dict):
        return []
    return [TagDef(name=PREFIX + name, type=data_type, initial=initial, description=description, access=Access.RO,
                   group=GROUP, runtime_only=True)
            for name, (data_type, initial, description) in STATUS_TAGS.items()]


def alarms(config: PlantConfig) -> list[tuple[tuple[str | int, ...], dict[str, Any]]]:
    """A broker that stays unreachable, a primary host that stays offline: alarms on the status tags."""
    section = config.raw.get(settings.SECTION)
    if not isinstance(section, dict):
        return []
    node = section.get("edge_node_id", config.name)
    found: list[tuple[tuple[str | int, ...], dict[str, Any]]] = [((settings.SECTION,), {
        "name": "sparkplug_disconnected",
        "discrete": {"tag": PREFIX + "connected", "value": False},
        "on_delay": "10s",
        "priority": "high",
        "suppress_when": f"not {PREFIX}running",
        "message": f"Sparkplug B edge node {node}: no connection to the MQTT broker",
        "description": "SCADA receives nothing from this plant. Check the broker (mqtt: url) and the network; the node reconnects by itself.",
    })]
    host = section.get("primary_host")
    if isinstance(host, str):
        found.append(((settings.SECTION, "primary_host"), {
            "name": "sparkplug_primary_host_offline",
            "discrete": {"tag": PREFIX + "primary_host_online", "value": False},
            "on_delay": "10s",
            "priority": "medium",
            "suppress_when": f"not {PREFIX}running or not {PREFIX}connected",
            "message": f"Sparkplug B primary host {host} offline: data is stored until it returns",
            "description": "The SCADA host application is not connected to the broker. Data is kept on disk (bounded) and forwarded as historical when it is back.",
        }))
    return found


def section_problems(config: PlantConfig) -> list[Problem]:
    return [config.problem(path, message) for path, message in settings.problems(config)]


SECTION = Section(path=(settings.SECTION,), schema=SCHEMA, problems=section_problems, tags=tags, alarms=alarms)
