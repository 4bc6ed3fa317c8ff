"""The JSON Schema of the `alarms:` section (structure only; `settings.py` checks the meaning).

It imports nothing that imports `softplc.config.schema`: that module builds the section with its own
DURATION (so `softplc schema` tightens durations here as everywhere), without an import cycle.
"""

from __future__ import annotations

from typing import Any

from softplc.storage.settings import STORAGE_PROPERTIES

PRIORITIES = ("low", "medium", "high", "critical")
LEVELS = ("hihi", "hi", "lo", "lolo")
KINDS = ("limit", "discrete", "condition", "increase")
SCALAR = {"type": ["boolean", "number", "string"]}


def alarms_schema(duration: dict[str, Any]) -> dict[str, Any]:
    """The schema of `alarms:`, with `duration` the schema of a duration value."""
    level = {
        "description": "The limit, or {limit: N, priority: P} to give this level its own priority.",
        "type": ["number", "object"],
        "properties": {"limit": {"type": "number"}, "priority": {"enum": list(PRIORITIES)}},
        "required": ["limit"],
        "additionalProperties": False,
    }
    limit = {
        "description": "Limit alarm on a numeric tag: active at or beyond the most severe limit crossed (hihi > hi, lo > lolo).",
        "type": "object",
        "properties": {
            "tag": {"type": "string", "description": "The numeric tag watched."},
            **{name: {**level, "description": f"{name} limit. " + level["description"]} for name in LEVELS},
            "deadband": {"type": "number", "minimum": 0, "description": "Returns to normal only this far back inside the limit (tag units; default 0)."},
        },
        "required": ["tag"],
        "additionalProperties": False,
    }
    discrete = {
        "description": "Discrete alarm: a tag in an alarm value (value:), off its normal value (normal:), or of bad quality.",
        "type": "object",
        "properties": {
            "tag": {"type": "string"},
            "value": {"description": "Active while the tag equals this value (or one of a list).", "type": ["boolean", "number", "string", "array"], "items": SCALAR},
            "normal": {"description": "Active while the tag differs from this value (or from every one of a list).", "type": ["boolean", "number", "string", "array"], "items": SCALAR},
            "bad_quality": {"type": "boolean", "description": "true: active while the tag's quality is not good (a robot or device away)."},
        },
        "required": ["tag"],
        "additionalProperties": False,
    }
    increase = {
        "description": "Active while a counter tag grew by at least `by` within the last `within` (e.g. scan overruns).",
        "type": "object",
        "properties": {
            "tag": {"type": "string"},
            "by": {"type": "number", "exclusiveMinimum": 0, "description": "Growth that raises the alarm (default 1)."},
            "within": duration,
        },
        "required": ["tag", "within"],
        "additionalProperties": False,
    }
    alarm = {
        "description": "An alarm: exactly one of limit, discrete, condition or increase, and how it is annunciated.",
        "type": "object",
        "properties": {
            "name": {"type": "string", "description": "Alarm name; with for_each it contains {TEMPLATE}, e.g. {task}_input_full."},
            "for_each": {"type": "string", "description": "A template name: one alarm per instance, {TEMPLATE} replaced in every text."},
            "description": {"type": "string", "description": "What it means and what the operator should do."},
            "limit": limit,
            "discrete": discrete,
            "condition": {"type": "string", "description": "Active while this expression over tags holds (the language of run --until)."},
            "increase": increase,
            "priority": {"enum": list(PRIORITIES), "description": "low, medium (default), high or critical."},
            "severity": {"type": "integer", "minimum": 1, "maximum": 1000, "description": "OPC UA Severity (default from the priority: 300/500/700/900)."},
            "message": {"type": "string", "description": "Text for the operator; {TAG} or {TAG:.1f} is a tag's value, also {value}, {limit}, {level}, {name}."},
            "latch": {"type": "boolean", "description": "true: stays annunciated after returning to normal until acknowledged."},
            "on_delay": duration,
            "off_delay": duration,
            "suppress_when": {"type": "string", "description": "Suppressed by design while this expression holds (e.g. the machine is stopped)."},
            "source": {"type": "string", "description": "The tag whose folder gets this alarm's OPC UA events (default: the tag watched)."},
        },
        "required": ["name"],
        "additionalProperties": False,
    }
    return {
        "description": "Alarms (ISA-18.2), their journal and their operator actions (docs/alarms.md).",
        "type": "object",
        "properties": {
            "shelve_max": {**duration, "description": "Longest time an alarm may stay shelved, timed or one-shot (default 8h)."},
            "definitions": {"type": "array", "items": alarm},
            "journal": {
                "description": "Where the journal of every transition and action is kept (default: SQLite alarms.sqlite in the state directory).",
                "type": "object",
                "properties": {
                    **STORAGE_PROPERTIES,
                    "retention": {"type": ["string", "number"], "description": "Drop rows older than this, e.g. 90d or 2w (default: keep all)."},
                },
                "additionalProperties": False,
            },
        },
        "additionalProperties": False,
    }
