"""The `alarms:` section of tagdb.yaml, checked against the plant's tags into alarm definitions.

    alarms:
      shelve_max: 8h
      definitions:
        - name: "{task}_input_full"          # one alarm per instance of the task template
          for_each: task
          limit: {tag: "{task}_iBL", hi: 95, deadband: 5}
          priority: high
          message: "Input buffer of {task} is {value:.0f} % full"

Every mistake is a located `Problem` (FILE:LINE:COL), all of them at once; a mistake in a
for_each declaration is reported once, not once per instance. `alarm_problems(config)` is the
check a configuration registry calls; `AlarmSettings.from_config(config)` raises ConfigError.

(Over 400 lines on purpose: the definitions and the one checker that builds them from the section
are one concept; the checker's parts share its problem bookkeeping, and apart they would each
need the other.)
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from softplc.adapters.alarms.messages import FIELDS, MessageError, placeholders
from softplc.adapters.alarms.schema import KINDS, LEVELS
from softplc.config.plant import PlantConfig
from softplc.config.schema import NAME_PATTERN, NAME_RULE
from softplc.config.system_tags import system_tag_definitions
from softplc.config.yamlsource import ConfigError, Location, Problem
from softplc.core.alarms import Priority
from softplc.core.datatypes import TypeMismatch
from softplc.core.expression import Condition, ExpressionError
from softplc.core.tags import TagDef
from softplc.storage.settings import parse_span, storage_problems
from softplc.util.durations import parse_duration
from softplc.util.suggest import did_you_mean

SECTION = "alarms"
DEFAULT_SHELVE_MAX = 8 * 3600.0
_HIGH = {"hihi": True, "hi": True, "lo": False, "lolo": False}
_DEFAULT_MESSAGES = {
    "limit": "{name}: {tag} = {value} ({level} limit {limit})",  # true at the activation and at the clear
    "discrete": "{name}: {tag} = {value}",
    "increase": "{name}: {tag} rose to {value}",
}


@dataclass(frozen=True)
class LimitLevel:
    """One limit of a limit alarm: hihi/hi are active at or above it, lo/lolo at or below."""

    name: str
    limit: float
    high: bool
    priority: Priority
    severity: int


@dataclass(frozen=True, eq=False)
class AlarmDefinition:
    """One alarm, template placeholders replaced and every name checked."""

    name: str
    kind: str  # limit, discrete, condition, increase
    tag: str  # the tag watched (a condition: its first tag)
    source: str  # the tag whose folder gets its OPC UA events
    group: str
    description: str
    priority: Priority
    severity: int
    message: str
    latching: bool = False
    on_delay: float = 0.0
    off_delay: float = 0.0
    reads: tuple[str, ...] = ()  # tags whose change re-evaluates the alarm
    levels: tuple[LimitLevel, ...] = ()  # limit: most severe first
    deadband: float = 0.0
    discrete: str = ""  # value | normal | bad_quality
    values: tuple[Any, ...] = ()
    condition: Condition | None = None
    increase_by: float = 1.0
    increase_within: float = 0.0
    suppress_when: Condition | None = None
    location: Location | None = None

    @property
    def limits(self) -> tuple[tuple[str, float], ...]:
        """(level, limit) of each level of a limit alarm."""
        return tuple((level.name, level.limit) for level in self.levels)


@dataclass(frozen=True)
class AlarmSettings:
    definitions: tuple[AlarmDefinition, ...] = ()
    shelve_max: float = DEFAULT_SHELVE_MAX
    journal: dict[str, Any] = field(default_factory=dict)  # the storage keys (softplc.storage.StorageSettings)
    retention: float | None = None  # journal rows older than this are dropped

    @classmethod
    def from_config(cls, config: PlantConfig) -> AlarmSettings:
        """The plant's alarms; raises ConfigError listing every problem."""
        checker = _Checker(config)
        settings = checker.check()
        if checker.problems:
            raise ConfigError(checker.problems)
        return settings

    @property
    def names(self) -> list[str]:
        return [definition.name for definition in self.definitions]


def configured(config: PlantConfig) -> bool:
    """Whether the plant has alarms: an `alarms:` section, or alarms another section adds (softplc.config.schema.Section.alarms)."""
    from softplc.config.sections import contributed_alarms

    return (isinstance(config.raw, dict) and config.raw.get(SECTION) is not None) or bool(contributed_alarms(config))


def alarm_problems(config: PlantConfig) -> list[Problem]:
    """The located problems of the `alarms:` section (empty when it is fine or absent)."""
    checker = _Checker(config)
    checker.check()
    return checker.problems


def known_tags(config: PlantConfig) -> dict[str, TagDef]:
    """Tags an alarm may read: the plant's, the runtime's `_sys.` diagnostics and those the sections add."""
    return {d.name: d for d in (*config.tags, *system_tag_definitions(config.tasks), *config.contributed_tags)}


class _Checker:
    def __init__(self, config: PlantConfig) -> None:
        self.config = config
        self.source = config.source
        self.problems: list[Problem] = []
        self.tags = known_tags(config)
        self.names: dict[str, Location] = {}
        # Problems of the declaration being checked, by where they are: one message per place.
        self._pending: dict[Location, tuple[str, int]] = {}

    def _where(self, path: Sequence[Any], at_key: bool = False) -> Location:
        if self.source is None:
            return Location(str(self.config.path), 1, 1)
        return self.source.key(path) if at_key else self.source.value(path)

    def problem(self, path: Sequence[Any], message: str, *, at_key: bool = False) -> None:
        where = self._where(path, at_key)
        first, count = self._pending.get(where, (message, 0))
        self._pending[where] = (first, count + 1)

    def _flush(self, template: str | None, instances: int) -> None:
        for where, (message, count) in self._pending.items():
            if template is not None and instances > 1:
                message += f" (for_each: {template}; the same in {count - 1} other instance(s))" if count > 1 else f" (instance of for_each: {template})"
            self.problems.append(Problem(where, message))
        self._pending.clear()

    def check(self) -> AlarmSettings:
        section = self.config.raw.get(SECTION) if isinstance(self.config.raw, dict) else None
        if not isinstance(section, dict):
            return AlarmSettings(tuple(self._contributed()))
        shelve_max = DEFAULT_SHELVE_MAX
        if "shelve_max" in section:
            shelve_max = self.duration(section["shelve_max"], (SECTION, "shelve_max"), "shelve_max", positive=True) or DEFAULT_SHELVE_MAX
            self._flush(None, 1)
        journal = section.get("journal") if isinstance(section.get("journal"), dict) else {}
        self.problems.extend(storage_problems(journal, (SECTION, "journal"), self.source))
        retention = None
        if "retention" in journal:
            try:
                retention = parse_span(journal["retention"])
            except (TypeError, ValueError) as error:
                self.problem((SECTION, "journal", "retention"), f"bad retention {journal['retention']!r}: {error}; e.g. 90d, 2w or 720h")
            else:
                if retention <= 0:
                    self.problem((SECTION, "journal", "retention"), f"bad retention {journal['retention']!r}: must be greater than zero")
            self._flush(None, 1)
        definitions: list[AlarmDefinition] = []
        for index, spec in enumerate(section.get("definitions") or []):
            if isinstance(spec, dict) and isinstance(spec.get("name"), str):
                definitions.extend(self.declaration(spec, (SECTION, "definitions", index)))
        storage = {key: value for key, value in journal.items() if key != "retention"}
        return AlarmSettings((*definitions, *self._contributed()), shelve_max, storage, retention)

    def _contributed(self) -> list[AlarmDefinition]:
        """The alarms other sections add, after the user's (a name the user took first is the section's problem)."""
        from softplc.config.sections import contributed_alarms

        return [definition for path, spec in contributed_alarms(self.config) for definition in self.declaration(spec, path)]

    def declaration(self, spec: dict[str, Any], path: tuple[Any, ...]) -> list[AlarmDefinition]:
        for_each = spec.get("for_each")
        if for_each is None:
            substitutions: list[dict[str, str]] = [{}]
        elif for_each in self.config.instances:
            substitutions = [{for_each: instance} for instance in self.config.instances[for_each]]
            if "{" + for_each + "}" not in spec["name"]:
                self.problem((*path, "name"), f"with for_each: {for_each}, the name must contain {{{for_each}}} so each alarm is unique")
                self._flush(None, 1)
                return []
        else:
            self.problem((*path, "for_each"), f"for_each must name a template; '{for_each}' is not one{did_you_mean(str(for_each), self.config.instances)}")
            self._flush(None, 1)
            return []
        result = []
        for substitution in substitutions:
            definition = self.definition(_substituted(spec, substitution), path)
            if definition is not None:
                result.append(definition)
        self._flush(for_each, len(substitutions))
        return result if len(result) == len(substitutions) else []

    def definition(self, spec: dict[str, Any], path: tuple[Any, ...]) -> AlarmDefinition | None:
        problems_before = sum(count for _, count in self._pending.values())
        name = spec["name"]
        if not re.match(NAME_PATTERN, name):
            self.problem((*path, "name"), f"invalid alarm name '{name}' ({NAME_RULE})")
        elif name in self.names:
            self.problem((*path, "name"), f"duplicate alarm name '{name}' (also at {self.names[name]})")
        else:
            self.names[name] = self._where((*path, "name"))
        kinds = [kind for kind in KINDS if kind in spec]
        if len(kinds) != 1:
            what = "none" if not kinds else " and ".join(kinds)
            self.problem(path, f"alarm '{name}' needs exactly one of {', '.join(KINDS)} (it has {what})")
            return None
        kind = kinds[0]
        fields: dict[str, Any] = {}
        reads: list[str] = []
        if kind == "limit":
            tag = self.limit(spec["limit"], (*path, "limit"), fields)
        elif kind == "discrete":
            tag = self.discrete(spec["discrete"], (*path, "discrete"), fields)
        elif kind == "increase":
            tag = self.increase(spec["increase"], (*path, "increase"), fields)
        else:
            condition = self.expression(spec["condition"], (*path, "condition"), "condition")
            fields["condition"] = condition
            tag = _first_tag(condition) if condition is not None else None
            if condition is not None and tag is None:
                self.problem((*path, "condition"), f"the condition of alarm '{name}' reads no tag, so it could never change")
            reads.extend(sorted(condition.names) if condition is not None else ())
        if tag is not None and tag not in reads:
            reads.insert(0, tag)
        suppress_when = None
        if "suppress_when" in spec:
            suppress_when = self.expression(spec["suppress_when"], (*path, "suppress_when"), "suppress_when")
            if suppress_when is not None:
                reads.extend(name for name in sorted(suppress_when.names) if name not in reads)
        source = tag
        if "source" in spec:
            source = self.tag_name(spec["source"], (*path, "source"), "source")
        delays = {key: self.duration(spec[key], (*path, key), key) or 0.0 for key in ("on_delay", "off_delay") if key in spec}
        priority = Priority(spec.get("priority", "medium"))
        severity = int(spec.get("severity", priority.severity))
        if "levels" in fields:  # a level without its own priority has the alarm's
            fields["levels"] = tuple(level if level.severity else replace(level, priority=priority, severity=severity) for level in fields["levels"])
        if kind == "condition":  # the expression itself says what is wrong (its braces made literal)
            default_message = "{name}: " + spec["condition"].replace("{", "{{").replace("}", "}}")
        else:
            default_message = _DEFAULT_MESSAGES[kind]
        message = spec.get("message", default_message)
        self.message(message, (*path, "message"), kind)
        if sum(count for _, count in self._pending.values()) > problems_before or tag is None or source is None:
            return None
        return AlarmDefinition(
            name=name, kind=kind, tag=tag, source=source, group=self.tags[source].group,
            description=str(spec.get("description", "")), priority=priority,
            severity=severity, message=message,
            latching=bool(spec.get("latch", False)), on_delay=delays.get("on_delay", 0.0), off_delay=delays.get("off_delay", 0.0),
            reads=tuple(reads), suppress_when=suppress_when, location=self._where((*path, "name")), **fields,
        )

    # -- kinds --------------------------------------------------------------------------

    def limit(self, spec: dict[str, Any], path: tuple[Any, ...], fields: dict[str, Any]) -> str | None:
        tag = self.numeric_tag(spec["tag"], (*path, "tag"), "limit alarm")
        levels: list[LimitLevel] = []
        for level in LEVELS:
            if level not in spec:
                continue
            value = spec[level]
            limit, priority = (value["limit"], value.get("priority")) if isinstance(value, dict) else (value, None)
            # severity 0: the level takes the alarm's priority and severity (known later)
            own = Priority(priority) if priority else Priority.MEDIUM
            levels.append(LimitLevel(level, float(limit), _HIGH[level], own, own.severity if priority else 0))
        if not levels:
            self.problem(path, f"a limit alarm needs at least one of {', '.join(LEVELS)}")
            return None
        limits = {level.name: level.limit for level in levels}
        for upper, lower in (("hihi", "hi"), ("hi", "lo"), ("lo", "lolo"), ("hihi", "lo"), ("hi", "lolo"), ("hihi", "lolo")):
            if upper in limits and lower in limits and not limits[upper] > limits[lower]:
                self.problem((*path, upper), f"{upper} {limits[upper]:g} must be above {lower} {limits[lower]:g}")
                break
        if tag is not None:
            definition = self.tags[tag]
            for level in levels:
                if level.high and definition.max is not None and level.limit > definition.max:
                    self.problem((*path, level.name), f"{level.name} {level.limit:g} is above the max {definition.max:g} of {tag}: the alarm could never be active")
                if not level.high and definition.min is not None and level.limit < definition.min:
                    self.problem((*path, level.name), f"{level.name} {level.limit:g} is below the min {definition.min:g} of {tag}: the alarm could never be active")
        fields["levels"] = tuple(levels)
        fields["deadband"] = float(spec.get("deadband", 0.0))
        return tag

    def discrete(self, spec: dict[str, Any], path: tuple[Any, ...], fields: dict[str, Any]) -> str | None:
        tag = self.tag_name(spec["tag"], (*path, "tag"), "discrete alarm")
        modes = [mode for mode in ("value", "normal", "bad_quality") if mode in spec]
        if len(modes) != 1 or spec.get("bad_quality") is False:
            self.problem(path, "a discrete alarm needs exactly one of value (its alarm value), normal (its normal value) or bad_quality: true")
            return None
        mode = modes[0]
        fields["discrete"] = mode
        if mode == "bad_quality" or tag is None:
            return tag
        given = spec[mode]
        values = given if isinstance(given, list) else [given]
        data_type = self.tags[tag].type
        coerced = []
        for index, value in enumerate(values):
            try:
                coerced.append(data_type.coerce(value))
            except TypeMismatch as error:
                where = (*path, mode, index) if isinstance(given, list) else (*path, mode)
                self.problem(where, f"{mode} {value!r} does not fit {tag} ({data_type.value}): {error}")
        fields["values"] = tuple(coerced)
        return tag

    def increase(self, spec: dict[str, Any], path: tuple[Any, ...], fields: dict[str, Any]) -> str | None:
        tag = self.numeric_tag(spec["tag"], (*path, "tag"), "increase alarm")
        fields["increase_by"] = float(spec.get("by", 1))
        fields["increase_within"] = self.duration(spec["within"], (*path, "within"), "within", positive=True) or 0.0
        return tag

    # -- parts --------------------------------------------------------------------------

    def tag_name(self, name: str, path: tuple[Any, ...], what: str) -> str | None:
        if name not in self.tags:
            self.problem(path, f"{what}: no tag '{name}'{did_you_mean(name, self.tags)}")
            return None
        return name

    def numeric_tag(self, name: str, path: tuple[Any, ...], what: str) -> str | None:
        tag = self.tag_name(name, path, what)
        if tag is not None and not self.tags[tag].type.is_numeric:
            self.problem(path, f"a {what} needs a numeric tag; {tag} is {self.tags[tag].type.value}")
            return None
        return tag

    def expression(self, text: str, path: tuple[Any, ...], what: str) -> Condition | None:
        try:
            return Condition(text, self.tags)
        except ExpressionError as error:
            self.problem(path, str(error) if what == "condition" else f"{what}: {error}")
            return None

    def duration(self, value: Any, path: tuple[Any, ...], what: str, *, positive: bool = False) -> float | None:
        try:
            seconds = parse_duration(value)
        except (TypeError, ValueError):
            self.problem(path, f"bad {what} {value!r}: write a duration such as 500ms, 10s or 2min")
            return None
        if positive and seconds <= 0:
            self.problem(path, f"bad {what} {value!r}: must be greater than zero")
            return None
        return seconds

    def message(self, text: str, path: tuple[Any, ...], kind: str) -> None:
        try:
            found = placeholders(text)
        except MessageError as error:
            self.problem(path, str(error))
            return
        for name, spec in found:
            if name in FIELDS:
                continue
            if name not in self.tags:
                self.problem(path, f"unknown placeholder {{{name}}} in message: not a tag{did_you_mean(name, self.tags)} nor one of {', '.join('{' + f + '}' for f in FIELDS)}")
                continue
            sample = self.tags[name].initial
            try:
                format(sample, spec)
            except (ValueError, TypeError) as error:
                self.problem(path, f"placeholder {{{name}:{spec}}}: {error} (a {self.tags[name].type.value} tag)")


def _substituted(spec: dict[str, Any], substitution: dict[str, str]) -> dict[str, Any]:
    """`spec` with {TEMPLATE} replaced by the instance in every string (keys stay)."""
    if not substitution:
        return spec

    def replace(value: Any) -> Any:
        if isinstance(value, str):
            for key, instance in substitution.items():
                value = value.replace("{" + key + "}", instance)
            return value
        if isinstance(value, dict):
            return {key: replace(item) for key, item in value.items()}
        if isinstance(value, list):
            return [replace(item) for item in value]
        return value

    return {key: (value if key == "for_each" else replace(value)) for key, value in spec.items()}


def _first_tag(condition: Condition) -> str | None:
    """The tag named first in the condition's text (its 'source' by default)."""
    if not condition.names:
        return None
    return min(condition.names, key=lambda name: (_position(condition.text, name), name))


def _position(text: str, name: str) -> int:
    match = re.search(r"(?<![\w.])" + re.escape(name) + r"(?![\w.])", text)
    return match.start() if match else len(text)

