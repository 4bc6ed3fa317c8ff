"""The `history:` section: where history is kept, for how long, and which tags are recorded how.

A recording rule names tags by glob patterns (`r*_xpos`) and says how to record them: on every
change, with an exception deadband (absolute, or `1%` of the tag's min..max range) and optionally
swinging-door compression. For each tag the matching rules are merged in order, later keys
winning; rules naming a tag exactly (e.g. from a tag's own `history:` key) come last. Plain data
and functions: the schema fragment `HISTORY_SCHEMA`, `HistorySettings.from_config` and `problems`.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.config.yamlsource import Problem
from softplc.storage.settings import (
    STORAGE_PROPERTIES,
    StorageSettings,
    parse_span,
    partitioned_spans,
    span_problems,
    storage_problems,
)

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.tags import TagDef

DEFAULT_FILE = "history.sqlite"
SIM_FILE = "history-sim.sqlite"  # --sim runs: simulated timestamps, never mixed with the plant's own
DEFAULT_PARTITION = 86400.0
DEFAULT_RETENTION = 30 * 86400.0
_SPAN_TEXT = {"description": "A duration: 10ms, 1s, 2min, 24h, 30d, 1w, or a number of seconds.", "type": ["string", "number"]}
_DEVIATION = {"description": "Absolute (0.01, in the tag's unit) or percent of the tag's min..max range ('1%').", "type": ["string", "number"]}

RULE_SCHEMA: dict[str, Any] = {
    "description": "How to record the tags it names; later rules override earlier ones key by key.",
    "type": "object",
    "properties": {
        "tags": {"description": "A glob pattern over tag names (r*_xpos) or a list of them.", "type": ["string", "array"], "items": {"type": "string"}},
        "record": {"type": "boolean", "description": "false: do not record these tags (default true)."},
        "deadband": {**_DEVIATION, "description": "Exception deadband: a new value is recorded only when it differs from the last recorded one by more than this."},
        "compression": {
            "description": "Swinging-door compression of what passes the deadband (numeric tags).",
            "type": "object",
            "properties": {
                "deviation": {**_DEVIATION, "description": "Largest error of a value read back by linear interpolation."},
                "min_interval": {**_SPAN_TEXT, "description": "No two stored values closer than this (default 0)."},
                "max_interval": {**_SPAN_TEXT, "description": "Store a value at least this often, even when nothing changes (heartbeat; default 1h)."},
            },
            "required": ["deviation"],
            "additionalProperties": False,
        },
    },
    "required": ["tags"],
    "additionalProperties": False,
}

HISTORY_SCHEMA: dict[str, Any] = {
    "description": "The historian (docs/history.md): where history is kept and which tags are recorded.",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: record nothing (default true when the section exists)."},
        **STORAGE_PROPERTIES,
        "retention": {**_SPAN_TEXT, "description": "Keep this much history; older partitions are dropped whole (default 30d)."},
        "partition": {**_SPAN_TEXT, "description": "Time span of one partition (table), a whole number of hours (default 1d)."},
        "sim": {"type": "boolean", "description": "Record --sim runs too, on the simulated clock, into STATE_DIR/history-sim.sqlite (default true)."},
        "record": {"type": "array", "items": RULE_SCHEMA, "description": "Recording rules, applied in order."},
    },
    "additionalProperties": False,
}


@dataclass(frozen=True)
class Deviation:
    """An absolute amount, or a percentage of a tag's range."""

    amount: float
    percent: bool = False

    def resolve(self, definition: TagDef) -> float | None:
        """The absolute amount for this tag; None when a percentage has no range to refer to."""
        if not self.percent:
            return self.amount
        if definition.min is None or definition.max is None:
            return None
        return self.amount / 100.0 * (definition.max - definition.min)


@dataclass(frozen=True)
class Compression:
    deviation: Deviation
    min_interval: float = 0.0
    max_interval: float = 3600.0


@dataclass(frozen=True)
class Rule:
    """One recording rule; `patterns` are globs (a rule from a tag's own key has its exact name)."""

    patterns: tuple[str, ...]
    record: bool | None = None
    deadband: Deviation | None = None
    compression: Compression | None = None
    path: tuple[Any, ...] = ()  # where it is written in the YAML
    exact: bool = False

    def matches(self, name: str) -> bool:
        if self.exact:
            return name in self.patterns
        return any(fnmatch.fnmatchcase(name, pattern) for pattern in self.patterns)


@dataclass(frozen=True)
class TagPolicy:
    """How one tag is recorded, resolved: absolute deadband, compression (or None), stepped or sloped."""

    deadband: float = 0.0
    compression: tuple[float, float, float] | None = None  # deviation, min interval, max interval
    stepped: bool = False


@dataclass(frozen=True)
class HistorySettings:
    enabled: bool = True
    section: Mapping[str, Any] = field(default_factory=dict)
    retention: float | None = DEFAULT_RETENTION
    partition: float = DEFAULT_PARTITION
    sim: bool = True
    rules: tuple[Rule, ...] = ()

    @classmethod
    def configured(cls, config: PlantConfig) -> bool:
        return isinstance(config.raw.get("history"), dict)

    @classmethod
    def from_config(cls, config: PlantConfig, extra_rules: Iterable[Rule] = ()) -> HistorySettings:
        """Settings of a checked configuration (call `problems` first); `extra_rules`: from tags' own keys."""
        section = config.raw.get("history") or {}
        rules = [_rule(spec, ("history", "record", index)) for index, spec in enumerate(section.get("record") or [])]
        retention, partition = partitioned_spans(section, DEFAULT_RETENTION, DEFAULT_PARTITION)
        return cls(
            enabled=bool(section.get("enabled", True)),
            section=section,
            retention=retention,
            partition=partition,
            sim=bool(section.get("sim", True)),
            rules=(*rules, *extra_rules),
        )

    def storage(self, state_dir: Path, *, simulated: bool = False) -> StorageSettings:
        """Where to record: the configured store, or for a --sim run always STATE_DIR/history-sim.sqlite."""
        return StorageSettings.for_run(self.section, state_dir, DEFAULT_FILE, SIM_FILE, simulated=simulated)

    def policies(self, definitions: Iterable[TagDef]) -> dict[str, TagPolicy]:
        """Each recorded tag's policy (tags no rule records are left out)."""
        ordered = sorted(self.rules, key=lambda rule: rule.exact)  # exact names after patterns, order kept
        result: dict[str, TagPolicy] = {}
        for definition in definitions:
            merged: dict[str, Any] = {}
            for rule in ordered:
                if rule.matches(definition.name):
                    merged["record"] = rule.record if rule.record is not None else merged.get("record", True)
                    if rule.deadband is not None:
                        merged["deadband"] = rule.deadband
                    if rule.compression is not None:
                        merged["compression"] = rule.compression
            if not merged.get("record", False):
                continue
            result[definition.name] = _policy(definition, merged)
        return result


def _policy(definition: TagDef, merged: Mapping[str, Any]) -> TagPolicy:
    kind = definition.type
    if not kind.is_float and not kind.is_integer:
        return TagPolicy(stepped=True)  # booleans and strings: every change, held until the next
    deadband = merged["deadband"].resolve(definition) if "deadband" in merged else 0.0
    compression = None
    spec: Compression | None = merged.get("compression")
    if spec is not None and kind.is_float:  # a straight line between integers is no integer: compress floats only
        deviation = spec.deviation.resolve(definition)
        if deviation is not None:
            compression = (deviation, spec.min_interval, spec.max_interval)
    return TagPolicy(deadband=deadband or 0.0, compression=compression, stepped=not kind.is_float)


def _deviation(value: Any) -> Deviation:
    if isinstance(value, str) and value.strip().endswith("%"):
        amount = float(value.strip()[:-1])
        percent = True
    elif isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"not an amount: {value!r} (write e.g. 0.01 or 1%)")
    else:
        amount, percent = float(value), False
    if not math.isfinite(amount) or amount < 0:
        raise ValueError(f"must be zero or more, not {value}")
    return Deviation(amount, percent)


def _rule(spec: Mapping[str, Any], path: tuple[Any, ...], *, exact: bool = False) -> Rule:
    patterns = spec.get("tags", ())
    patterns = (patterns,) if isinstance(patterns, str) else tuple(patterns)
    compression = None
    if isinstance(spec.get("compression"), Mapping):
        c = spec["compression"]
        compression = Compression(_deviation(c["deviation"]), parse_span(c.get("min_interval", 0)), parse_span(c.get("max_interval", 3600)))
    return Rule(patterns, spec.get("record"), _deviation(spec["deadband"]) if "deadband" in spec else None, compression, path, exact)


def tag_rule(name: str, spec: Mapping[str, Any] | bool, path: tuple[Any, ...] = ()) -> Rule:
    """The rule of a tag's own `history:` key (`true`, or the keys of a rule without `tags`)."""
    if isinstance(spec, bool):
        return Rule((name,), spec, path=path, exact=True)
    return _rule({**spec, "tags": name}, path, exact=True)


def problems(config: PlantConfig, definitions: Sequence[TagDef] | None = None) -> list[Problem]:
    """Located mistakes of the `history:` section that its schema cannot see."""
    section = config.raw.get("history")
    source = config.source
    if not isinstance(section, Mapping) or source is None:
        return []
    if definitions is None:
        from softplc.config.system_tags import system_tag_definitions

        definitions = [*config.tags, *system_tag_definitions(config.tasks)]
    found = storage_problems(section, ("history",), source) + span_problems(section, ("history",), source)

    def at(path: Sequence[Any], message: str) -> None:
        found.append(source.problem(path, message))

    rules = section.get("record")
    if not isinstance(rules, list):
        return found
    names = [definition.name for definition in definitions]
    by_name = {definition.name: definition for definition in definitions}
    for index, spec in enumerate(rules):
        base = ("history", "record", index)
        if not isinstance(spec, Mapping):
            continue
        patterns = spec.get("tags")
        listed = [patterns] if isinstance(patterns, str) else patterns if isinstance(patterns, list) else []
        matched: list[str] = []
        for position, pattern in enumerate(listed):
            if not isinstance(pattern, str):
                continue
            hits = fnmatch.filter(names, pattern)
            if not hits:
                where = base + ("tags",) if isinstance(patterns, str) else base + ("tags", position)
                at(where, f"tag pattern '{pattern}' matches no tag")
            matched += hits
        amounts = [(base + ("deadband",), spec.get("deadband"))]
        compression = spec.get("compression")
        if isinstance(compression, Mapping):
            amounts.append((base + ("compression", "deviation"), compression.get("deviation")))
            for key in ("min_interval", "max_interval"):
                if key in compression:
                    try:
                        seconds = parse_span(compression[key])
                        if key == "max_interval" and seconds <= 0:
                            raise ValueError("must be more than 0")
                    except (TypeError, ValueError) as error:
                        at(base + ("compression", key), f"bad {key} {compression[key]!r}: {error}")
        for path, value in amounts:
            if value is None:
                continue
            try:
                deviation = _deviation(value)
            except ValueError as error:
                at(path, f"bad {path[-1]} {value!r}: {error}")
                continue
            if deviation.percent:
                unbounded = [n for n in matched if by_name[n].type.is_float or by_name[n].type.is_integer
                             if by_name[n].min is None or by_name[n].max is None]
                if unbounded:
                    shown = ", ".join(unbounded[:3]) + (f" and {len(unbounded) - 3} more" if len(unbounded) > 3 else "")
                    at(path, f"{path[-1]} {value} is a percentage of the tag's range, but {shown} has no min and max; give an absolute amount")
    return found
