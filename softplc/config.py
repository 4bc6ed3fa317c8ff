"""Load and validate a plant configuration (`tagdb.yaml`) into checked, expanded settings.

Every mistake becomes a `Problem` with `FILE:LINE:COL`; all problems of a file are reported
together by raising `ConfigError`. Nothing here starts anything.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import math
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.datatypes import DataType, TypeMismatch
from softplc.durations import parse_duration
from softplc.program import Program
from softplc.scan import RestartPolicy
from softplc.schema import CONFIG_SCHEMA, NAME_PATTERN, NAME_RULE
from softplc.suggest import did_you_mean
from softplc.tags import Access, TagDef
from softplc.yamlsource import ConfigError, Location, Problem, SourceMap, load_yaml, parse_yaml

if TYPE_CHECKING:
    import jsonschema

SYSTEM_PREFIX = "_sys."


@dataclass
class ProgramConfig:
    name: str
    reference: str
    cls: type[Program]
    bindings: dict[str, str | list[str]]
    params: dict[str, Any]
    restart: RestartPolicy
    enabled: bool = True
    location: Location | None = None  # where the program is named in the file (for errors)


@dataclass
class TaskConfig:
    name: str
    interval: float
    priority: int
    watchdog: float
    programs: list[ProgramConfig]


@dataclass
class PlantConfig:
    """A validated plant: tag definitions (templates expanded), tasks, and adapter settings."""

    path: Path
    name: str
    description: str
    tags: list[TagDef]
    instances: dict[str, list[str]]  # template name → instance names
    tasks: list[TaskConfig]
    servers: dict[str, Any] = field(default_factory=dict)
    runtime: dict[str, Any] = field(default_factory=dict)
    raw: dict[str, Any] = field(default_factory=dict)
    source: SourceMap | None = None

    @property
    def base_dir(self) -> Path:
        return self.path.parent

    @property
    def state_dir(self) -> Path:
        return self.base_dir / self.runtime.get("state_dir", ".softplc")

    @property
    def program_count(self) -> int:
        return sum(len(task.programs) for task in self.tasks)

    def tag(self, name: str) -> TagDef:
        for definition in self.tags:
            if definition.name == name:
                return definition
        raise KeyError(name)


def load_config(path: str | Path) -> PlantConfig:
    """Load and check a configuration file; raise ConfigError listing every problem."""
    path = Path(path)
    data, source = load_yaml(path)
    return _Checker(path, data, source).check()


def parse_config(text: str, path: str | Path = "<string>") -> PlantConfig:
    """Check configuration text as if read from `path` (programs resolve relative to it)."""
    data, source = parse_yaml(text, str(path))
    return _Checker(Path(path), data, source).check()


# -- structural checks (JSON Schema) --------------------------------------------------------


def _describe(value: Any) -> str:
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, (int, float)):
        return f"number {value}"
    if isinstance(value, str):
        return f"string '{value}'"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return "null" if value is None else type(value).__name__


_TYPE_WORDS = {"object": "a mapping", "array": "a list", "string": "a string", "number": "a number",
               "integer": "an integer", "boolean": "true or false", "null": "null"}


def _schema_problems(data: Any, source: SourceMap) -> tuple[list[Problem], set[tuple[Any, ...]]]:
    return _schema_check(data, source, CONFIG_SCHEMA)


def schema_problems(data: Any, source: SourceMap, schema: dict[str, Any]) -> list[Problem]:
    """Check `data` against a JSON Schema; each violation becomes a located, readable Problem."""
    return _schema_check(data, source, schema)[0]


def _schema_check(data: Any, source: SourceMap, schema: dict[str, Any]) -> tuple[list[Problem], set[tuple[Any, ...]]]:
    """The schema's problems, and the paths they are about (semantic checks skip those)."""
    import jsonschema  # ~60 ms to import: only commands that load a configuration pay for it

    validator = jsonschema.Draft202012Validator(schema)
    problems: list[Problem] = []
    paths: set[tuple[Any, ...]] = set()
    for error in validator.iter_errors(data):
        path = tuple(error.absolute_path)
        if "propertyNames" in error.absolute_schema_path:
            path = (*path, error.instance)  # the error is about a key: point at that key
        if error.validator == "additionalProperties" and isinstance(error.instance, dict):
            known = error.schema.get("properties", {})
            paths.update((*path, key) for key in error.instance if key not in known)
        else:
            paths.add(path)
        problems.extend(_translate(error, path, source))
    return problems, paths


def _translate(error: jsonschema.ValidationError, path: tuple[Any, ...], source: SourceMap) -> list[Problem]:
    kind = error.validator
    if not path:
        where = "the file"
    elif isinstance(path[-1], int):  # a list item: name the list, not the index
        where = f"item {path[-1] + 1} of '{path[-2]}'" if len(path) > 1 else f"item {path[-1] + 1}"
    else:
        where = f"'{path[-1]}'"
    if kind == "additionalProperties":
        known = list(error.schema.get("properties", {}))
        unknown = [key for key in error.instance if key not in known]
        problems = []
        for key in unknown:
            hint = did_you_mean(key, known)
            expected = f"; expected one of: {', '.join(known)}" if not hint and known else ""
            problems.append(source.problem((*path, key), f"unknown key '{key}'{hint}{expected}", at_key=True))
        return problems
    if kind == "required":
        missing = error.message.split("'")[1] if "'" in error.message else error.message
        return [source.problem(path, f"{where} is missing the required key '{missing}'", at_key=True)]
    if kind == "enum":
        choices = [str(choice) for choice in error.validator_value]
        value = error.instance
        shown = f"'{value}'" if isinstance(value, str) else _describe(value)
        what = f"type {shown}" if path and path[-1] == "type" else f"value {shown} for {where}"
        hint = did_you_mean(str(value), choices)
        return [source.problem(path, f"unknown {what}{hint}; expected one of: {', '.join(choices)}")]
    if kind == "type":
        expected = error.validator_value
        expected_words = " or ".join(_TYPE_WORDS.get(t, t) for t in ([expected] if isinstance(expected, str) else expected))
        return [source.problem(path, f"{where} must be {expected_words}, not {_describe(error.instance)}")]
    if kind == "pattern":
        is_key = "propertyNames" in error.absolute_schema_path
        return [source.problem(path, f"invalid name '{error.instance}' ({NAME_RULE})", at_key=is_key)]
    if kind == "const":
        return [source.problem(path, f"{where} must be {error.validator_value!r}, not {_describe(error.instance)}")]
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        relation = {"minimum": "at least", "maximum": "at most", "exclusiveMinimum": "more than", "exclusiveMaximum": "less than"}[kind]
        return [source.problem(path, f"{where} must be {relation} {error.validator_value}, not {error.instance}")]
    return [source.problem(path, f"{where}: {error.message}")]


# -- semantic checks ------------------------------------------------------------------------


class _Checker:
    def __init__(self, path: Path, data: Any, source: SourceMap) -> None:
        self.path = path
        self.data = data
        self.source = source
        self.problems: list[Problem] = []
        self.tags: dict[str, TagDef] = {}
        self.tag_paths: dict[str, tuple[Any, ...]] = {}
        self.instances: dict[str, list[str]] = {}
        self.schema_paths: set[tuple[Any, ...]] = set()
        # template → instance → tag → (initial value, where it is written), from instances_from
        self.external_initial: dict[str, dict[str, dict[str, tuple[Any, Location]]]] = {}

    def problem(self, path: Sequence[Any], message: str, *, at_key: bool = False) -> None:
        if tuple(path) in self.schema_paths:
            return  # the schema already explained what is wrong here; say it once
        self.problems.append(self.source.problem(path, message, at_key=at_key))

    def check(self) -> PlantConfig:
        data = self.data
        if data is None:
            raise ConfigError([self.source.problem((), "the file is empty: expected a plant configuration (version, tags, tasks...)")])
        if not isinstance(data, dict):
            raise ConfigError([self.source.problem((), f"the file must be a mapping of sections, not {_describe(data)}")])
        schema_problems, self.schema_paths = _schema_problems(data, self.source)
        self.problems.extend(schema_problems)
        # Semantic checks run on whatever is well-formed, so one pass reports as much as possible.
        self._check_templates(data.get("templates"))
        self._check_plain_tags(data.get("tags"))
        tasks = self._check_tasks(data.get("tasks"))
        self._check_runtime(data.get("runtime"))
        if self.problems:
            raise ConfigError(self.problems)
        plant = data.get("plant") or {}
        return PlantConfig(
            path=self.path,
            name=plant.get("name", self.path.stem),
            description=plant.get("description", ""),
            tags=list(self.tags.values()) + _contributed_tags(data),
            instances=self.instances,
            tasks=tasks,
            servers=data.get("servers") or {},
            runtime=data.get("runtime") or {},
            raw=data,
            source=self.source,
        )

    # -- tags ---------------------------------------------------------------------------

    def _check_templates(self, templates: Any) -> None:
        if not isinstance(templates, dict):
            return
        for template_name, template in templates.items():
            base = ("templates", template_name)
            if not isinstance(template, dict):
                continue
            instances = self._template_instances(template_name, template, base)
            self.instances[template_name] = instances
            tag_specs = template.get("tags") if isinstance(template.get("tags"), dict) else {}
            overrides = template.get("initial") if isinstance(template.get("initial"), dict) else {}
            for instance, values in overrides.items():
                if instance not in instances:
                    self.problem((*base, "initial", instance), f"'{instance}' is not an instance of template '{template_name}'{did_you_mean(instance, instances)}", at_key=True)
                    continue
                if not isinstance(values, dict):
                    continue
                for tag_name in values:
                    if tag_name not in tag_specs:
                        self.problem((*base, "initial", instance, tag_name), f"template '{template_name}' has no tag '{tag_name}'{did_you_mean(tag_name, tag_specs)}", at_key=True)
            group_root = template.get("group", template_name.capitalize() + "s")
            external = self.external_initial.get(template_name, {})
            for instance in instances:
                instance_overrides = overrides.get(instance) if isinstance(overrides.get(instance), dict) else {}
                from_file = external.get(instance, {})
                for tag_name, spec in tag_specs.items():
                    full_name = f"{instance}_{tag_name}"
                    override: tuple[Any, tuple[Any, ...] | Location] | None = None
                    if tag_name in instance_overrides:
                        override = (instance_overrides[tag_name], (*base, "initial", instance, tag_name))
                    elif tag_name in from_file:
                        override = from_file[tag_name]
                    self._add_tag(
                        full_name,
                        spec,
                        (*base, "tags", tag_name),
                        default_group=f"{group_root}/{instance}",
                        initial_override=override,
                    )

    def _template_instances(self, name: str, template: dict[str, Any], base: tuple[Any, ...]) -> list[str]:
        explicit = template.get("instances")
        count = template.get("count")
        if explicit is not None and count is not None:
            self.problem((*base, "count"), "give either 'instances' or 'count', not both", at_key=True)
        if "instances_from" in template:
            if explicit is not None or count is not None:
                self.problem((*base, "instances_from"), "give only one of 'instances', 'count' or 'instances_from'", at_key=True)
            return self._instances_from(name, template, base)
        if isinstance(explicit, list):
            seen: set[str] = set()
            result = []
            for index, instance in enumerate(explicit):
                if not isinstance(instance, str):
                    continue
                if instance in seen:
                    self.problem((*base, "instances", index), f"duplicate instance '{instance}'")
                    continue
                seen.add(instance)
                result.append(instance)
            return result
        if isinstance(count, int) and not isinstance(count, bool) and count >= 1:
            prefix = template.get("prefix", name[:1])
            width = max(2, len(str(count)))
            return [f"{prefix}{index:0{width}d}" for index in range(1, count + 1)]
        mistyped = any(path[: len(base)] == base for path in self.schema_paths)  # e.g. 'instance:', already reported
        if explicit is None and count is None and not mistyped:
            self.problem(base, f"template '{name}' needs 'instances' (a list of names) or 'count'", at_key=True)
        return []

    def _instances_from(self, name: str, template: dict[str, Any], base: tuple[Any, ...]) -> list[str]:
        """Instance names from the `id` of each item of a YAML list in another file, plus initial values."""
        spec = template["instances_from"]
        where = (*base, "instances_from")
        if isinstance(spec, str):
            spec = {"file": spec}
        elif isinstance(spec, dict) and isinstance(spec.get("file"), str):
            where = (*where, "file")
        else:
            return []  # the schema reported it
        file = self.path.parent / spec["file"]
        if not file.is_file():
            self.problem(where, f"instances_from: file not found: {file}")
            return []
        try:
            data, source = load_yaml(file)
        except ConfigError as error:
            self.problems.extend(error.problems)
            return []
        items, prefix = self._external_list(data, source, spec.get("key"), where, file)
        if items is None:
            return []
        result: list[str] = []
        for index, item in enumerate(items):
            item_id = item.get("id") if isinstance(item, dict) else None
            if not isinstance(item_id, str) or not _is_name(item_id):
                what = f"its id {item_id!r} is not a valid name ({NAME_RULE})" if item_id is not None else "it has no 'id'"
                self.problems.append(source.problem((*prefix, index), f"item {index + 1} cannot be an instance of template '{name}': {what}"))
                continue
            if item_id in result:
                self.problems.append(source.problem((*prefix, index, "id"), f"duplicate id '{item_id}'"))
                continue
            result.append(item_id)
        initial = spec.get("initial") if isinstance(spec.get("initial"), dict) else {}
        tag_specs = template.get("tags") if isinstance(template.get("tags"), dict) else {}
        values: dict[str, dict[str, tuple[Any, Location]]] = {item_id: {} for item_id in result}
        for tag_name, dotted in initial.items():
            if tag_name not in tag_specs:
                self.problem((*base, "instances_from", "initial", tag_name), f"template '{name}' has no tag '{tag_name}'{did_you_mean(tag_name, tag_specs)}", at_key=True)
                continue
            if not isinstance(dotted, str):
                continue
            keys = dotted.split(".")
            found = 0
            for index, item in enumerate(items):
                value = item
                for key in keys:
                    value = value.get(key) if isinstance(value, dict) else None
                if isinstance(item, dict) and item.get("id") in values and value is not None:
                    values[item["id"]][tag_name] = (value, source.value((*prefix, index, *keys)))
                    found += 1
            if not found:  # a key missing from every item is a typo, not an optional value
                self.problem((*base, "instances_from", "initial", tag_name), f"no item of {file} has '{dotted}'")
        self.external_initial[name] = values
        return result

    def _external_list(self, data: Any, source: SourceMap, key: Any, where: tuple[Any, ...], file: Path) -> tuple[list[Any] | None, tuple[Any, ...]]:
        """The list of items in an instances_from file: the file itself, or its (only) list entry."""
        if isinstance(key, str):
            if isinstance(data, dict) and isinstance(data.get(key), list):
                return data[key], (key,)
            self.problem(where, f"instances_from: {file} has no list under '{key}'")
            return None, ()
        if isinstance(data, list):
            return data, ()
        lists = [k for k, v in data.items() if isinstance(v, list)] if isinstance(data, dict) else []
        if len(lists) == 1:
            return data[lists[0]], (lists[0],)
        found = f"several lists ({', '.join(lists)}): name one with 'key'" if lists else "no list of items with 'id'"
        self.problem(where, f"instances_from: {file} has {found}")
        return None, ()

    def _problem_at(self, where: tuple[Any, ...] | Location, message: str) -> None:
        """A problem at a path of this file, or at a location in another file (instances_from)."""
        if isinstance(where, Location):
            self.problems.append(Problem(where, message))
        else:
            self.problem(where, message)

    def _check_plain_tags(self, tags: Any) -> None:
        if not isinstance(tags, dict):
            return
        for name, spec in tags.items():
            self._add_tag(name, spec, ("tags", name), default_group="")

    def _add_tag(
        self,
        name: str,
        spec: Any,
        path: tuple[Any, ...],
        *,
        default_group: str,
        initial_override: tuple[Any, tuple[Any, ...] | Location] | None = None,
    ) -> None:
        if not isinstance(spec, dict) or not isinstance(name, str):
            return
        if name in self.tags:
            first = self.source.key(self.tag_paths[name])
            self.problem(path, f"duplicate tag '{name}' (also defined at {first})", at_key=True)
            return
        if name.startswith("_sys"):
            self.problem(path, f"tag names starting with '_sys' are reserved for system tags: '{name}'", at_key=True)
            return
        try:
            data_type = DataType(spec.get("type"))
        except ValueError:
            return  # the schema already reported the unknown type
        ok = True
        low, high = spec.get("min"), spec.get("max")
        for bound_name, bound in (("min", low), ("max", high)):
            if isinstance(bound, (int, float)) and not isinstance(bound, bool):
                if not data_type.is_numeric:
                    self.problem((*path, bound_name), f"'{bound_name}' is only allowed for numeric tags, not {data_type.value}", at_key=True)
                    ok = False
                elif bound != bound:
                    self.problem((*path, bound_name), f"{bound_name} must be a number, not NaN")
                    ok = False
                else:
                    try:
                        data_type.coerce(bound)
                    except TypeMismatch as error:
                        self.problem((*path, bound_name), f"{bound_name} {bound}: {error}")
                        ok = False
        if isinstance(low, (int, float)) and isinstance(high, (int, float)) and low > high:
            self.problem((*path, "min"), f"min {low} is greater than max {high}")
            ok = False
        if initial_override is not None:
            initial, initial_path = initial_override
        else:
            initial, initial_path = spec.get("initial", data_type.default), (*path, "initial")
        # Without an `initial` the tag starts at its type's default, which may break min/max.
        hint = "" if initial_override is not None or "initial" in spec else f" (no 'initial' is given, so it starts at {data_type.default}: add one)"
        try:
            initial = data_type.coerce(initial)
        except TypeMismatch as error:
            self._problem_at(initial_path, f"initial value of '{name}' is invalid: {error}")
            ok = False
        else:
            if data_type.is_numeric and ok:
                if initial != initial and (low is not None or high is not None):
                    self._problem_at(initial_path, f"initial value of '{name}' is NaN, which is outside the range of a bounded tag")
                    ok = False
                elif isinstance(low, (int, float)) and initial < low:
                    self._problem_at(initial_path, f"initial value {initial} of '{name}' is below its min {low}{hint}")
                    ok = False
                if isinstance(high, (int, float)) and initial > high:
                    self._problem_at(initial_path, f"initial value {initial} of '{name}' is above its max {high}{hint}")
                    ok = False
        if not ok:
            return
        options = {key: spec[key] for key in ("modbus",) if key in spec}
        self.tags[name] = TagDef(
            name=name,
            type=data_type,
            initial=initial,
            unit=str(spec.get("unit", "")),
            description=str(spec.get("description", "")),
            access=Access(spec.get("access", "rw")) if spec.get("access", "rw") in ("rw", "ro") else Access.RW,
            min=low if isinstance(low, (int, float)) and not isinstance(low, bool) else None,
            max=high if isinstance(high, (int, float)) and not isinstance(high, bool) else None,
            retain=bool(spec.get("retain", False)),
            group=str(spec.get("group", default_group)),
            options=options,
        )
        self.tag_paths[name] = path

    # -- tasks and programs -------------------------------------------------------------

    def _duration(self, value: Any, path: tuple[Any, ...], what: str) -> float | None:
        if isinstance(value, float) and not math.isfinite(value):
            self.problem(path, f"bad {what} {value!r}: must be a finite duration such as 10ms, 100ms or 1s")
            return None
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value <= 0:
            self.problem(path, f"bad {what} {value!r}: must be greater than zero")
            return None
        try:
            seconds = parse_duration(value)
        except (ValueError, TypeError):
            self.problem(path, f"bad {what} {value!r}: write a duration such as 10ms, 100ms or 1s")
            return None
        if seconds <= 0:
            self.problem(path, f"bad {what} {value!r}: must be greater than zero")
            return None
        return seconds

    def _check_tasks(self, tasks: Any) -> list[TaskConfig]:
        result: list[TaskConfig] = []
        if not isinstance(tasks, dict):
            return result
        program_names: dict[str, tuple[Any, ...]] = {}
        for task_name, task in tasks.items():
            base = ("tasks", task_name)
            if not isinstance(task, dict):
                continue
            interval = self._duration(task.get("interval"), (*base, "interval"), "interval") if "interval" in task else None
            if interval is not None and interval < 1e-4:
                self.problem((*base, "interval"), f"bad interval {task['interval']!r}: the shortest supported interval is 100us")
                interval = None
            watchdog = None
            if "watchdog" in task:
                watchdog = self._duration(task["watchdog"], (*base, "watchdog"), "watchdog")
            programs: list[ProgramConfig] = []
            for index, spec in enumerate(task.get("programs") or []):
                for program in self._check_program(spec, (*base, "programs", index)):
                    if program.name in program_names:
                        first = self.source.value(program_names[program.name])
                        self.problem((*base, "programs", index, "name"), f"duplicate program name '{program.name}' (also used at {first})")
                        continue
                    program_names[program.name] = (*base, "programs", index, "name")
                    programs.append(program)
            if interval is None:
                continue
            priority = task.get("priority", 10)
            result.append(
                TaskConfig(
                    name=task_name,
                    interval=interval,
                    priority=priority if isinstance(priority, int) else 10,
                    watchdog=watchdog if watchdog is not None else interval,
                    programs=programs,
                )
            )
        return result

    def _check_program(self, spec: Any, path: tuple[Any, ...]) -> list[ProgramConfig]:
        if not isinstance(spec, dict) or not isinstance(spec.get("program"), str) or not isinstance(spec.get("name"), str):
            return []
        cls = self._import_program(spec["program"], (*path, "program"))
        for_each = spec.get("for_each")
        if for_each is None:
            substitutions: list[dict[str, str]] = [{}]
        elif isinstance(for_each, str) and for_each in self.instances:
            substitutions = [{for_each: instance} for instance in self.instances[for_each]]
        else:
            self.problem((*path, "for_each"), f"for_each must name a template; '{for_each}' is not one{did_you_mean(str(for_each), self.instances)}")
            return []
        if for_each is not None and "{" + for_each + "}" not in spec["name"]:
            self.problem((*path, "name"), f"with for_each: {for_each}, the name must contain {{{for_each}}} so each instance is unique")
            return []
        restart = RestartPolicy(
            on_fault=spec.get("on_fault", "stop") if spec.get("on_fault") in ("stop", "restart") else "stop",
            delay=(self._duration(spec["restart_delay"], (*path, "restart_delay"), "restart_delay") or 1.0) if "restart_delay" in spec else 1.0,
            max_restarts=spec.get("max_restarts", 3) if isinstance(spec.get("max_restarts", 3), int) else 3,
        )
        results = []
        for substitution in substitutions:
            name = _substitute(spec["name"], substitution)
            bindings = self._check_bindings(cls, spec.get("bind") or {}, substitution, path, name)
            params = self._check_params(cls, spec.get("params") or {}, substitution, path, name)
            if cls is None or bindings is None or params is None:
                continue
            location = self.source.value((*path, "program"))
            results.append(ProgramConfig(name, spec["program"], cls, bindings, params, restart, bool(spec.get("enabled", True)), location))
        return results

    def _import_program(self, reference: str, path: tuple[Any, ...]) -> type[Program] | None:
        try:
            cls = import_program(reference, self.path.parent)
        except ImportError as error:
            self.problem(path, str(error))
            return None
        return cls

    def _check_bindings(
        self, cls: type[Program] | None, bind: Any, substitution: dict[str, str], path: tuple[Any, ...], name: str
    ) -> dict[str, str | list[str]] | None:
        if not isinstance(bind, dict):
            return None
        ok = True
        bindings: dict[str, str | list[str]] = {}
        variables = cls.variables if cls is not None else {}
        for var, target in bind.items():
            var_path = (*path, "bind", var)
            if cls is not None and var not in variables:
                known = ", ".join(variables) or "none"
                self.problem(var_path, f"program {cls.__name__} has no variable '{var}'{did_you_mean(var, variables)}; its variables: {known}", at_key=True)
                ok = False
                continue
            targets = [target] if isinstance(target, str) else target if isinstance(target, list) else []
            resolved = []
            for index, tag in enumerate(targets):
                if not isinstance(tag, str):
                    continue
                tag = _substitute(tag, substitution)
                if tag not in self.tags:
                    where = var_path if isinstance(target, str) else (*var_path, index)
                    if tag.startswith(SYSTEM_PREFIX):
                        self.problem(where, f"'{var}' of program '{name}' is bound to the system tag '{tag}': programs bind plant tags only "
                                     "(system tags are read by clients, --until and the HMI)")
                    else:
                        self.problem(where, f"'{var}' of program '{name}' is bound to a missing tag '{tag}'{did_you_mean(tag, self.tags)}")
                    ok = False
                resolved.append(tag)
            bindings[var] = resolved[0] if isinstance(target, str) else resolved
        if cls is not None:
            for var, variable in variables.items():
                if var not in bind and not variable.optional:
                    where = (*path, "bind") if (*path, "bind") in self.source.keys else path
                    self.problem(where, f"variable '{var}' of program '{name}' ({cls.__name__}) is not bound to a tag", at_key=True)
                    ok = False
        return bindings if ok and cls is not None else None

    def _check_params(
        self, cls: type[Program] | None, params: Any, substitution: dict[str, str], path: tuple[Any, ...], name: str
    ) -> dict[str, Any] | None:
        if cls is None or not isinstance(params, dict):
            return None
        ok = True
        result: dict[str, Any] = {}
        for key, value in params.items():
            param = cls.params.get(key)
            if param is None:
                known = ", ".join(cls.params) or "none"
                self.problem((*path, "params", key), f"program {cls.__name__} has no parameter '{key}'{did_you_mean(key, cls.params)}; its parameters: {known}", at_key=True)
                ok = False
                continue
            if isinstance(value, str):
                value = _substitute(value, substitution)
            try:
                result[key] = param.convert(value)
            except ValueError as error:
                self.problem((*path, "params", key), f"parameter '{key}' of program '{name}': {error}")
                ok = False
        for key, param in cls.params.items():
            if param.required and key not in params:
                self.problem(path, f"program '{name}' needs the parameter '{key}' ({param.description or 'no default'})", at_key=True)
                ok = False
        return result if ok else None

    def _check_runtime(self, runtime: Any) -> None:
        if isinstance(runtime, dict) and "stall_after" in runtime:
            self._duration(runtime["stall_after"], ("runtime", "stall_after"), "stall_after")


def _contributed_tags(data: dict[str, Any]) -> list[TagDef]:
    """Tags other sections add to the plant: the alarm summary tags (`_sys.alarms.*`) with `alarms:`.

    Marked stopgap: the configuration registry (branch `config`) takes such tag contributions
    over at merge. They come last, so no other tag's Modbus address moves.
    """
    if isinstance(data.get("alarms"), dict):
        from softplc.alarms.summary import summary_tag_definitions

        return summary_tag_definitions()
    return []


def _is_name(text: str) -> bool:
    return re.match(NAME_PATTERN, text) is not None


def _substitute(text: str, substitution: dict[str, str]) -> str:
    for key, value in substitution.items():
        text = text.replace("{" + key + "}", value)
    return text


def import_program(reference: str, base_dir: Path) -> type[Program]:
    """Resolve `module:Class`, `module.Class` or `file.py:Class` to a Program subclass.

    `base_dir` (the configuration's folder) is importable, so `programs.x:Y` finds the
    plant's own `programs/` folder.
    """
    if ":" in reference:
        module_name, _, class_name = reference.rpartition(":")
    else:
        module_name, _, class_name = reference.rpartition(".")
    if not module_name or not class_name:
        raise ImportError(f"cannot load program '{reference}': write module:Class, e.g. programs.plant:PlantSimulator")
    try:
        if module_name.endswith(".py"):
            file = (base_dir / module_name).resolve()
            spec = importlib.util.spec_from_file_location(f"softplc_user_{file.stem}", file)
            if spec is None or spec.loader is None or not file.exists():
                raise ImportError(f"no such file {file}")
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
        else:
            base = str(base_dir.resolve())
            if base not in sys.path:
                sys.path.insert(0, base)
            module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        missing = error.name or ""
        if module_name == missing or module_name.startswith(missing + "."):
            where = f"{base_dir.resolve()} (the configuration's folder) or the installed packages"
            raise ImportError(f"cannot load program '{reference}': no module named '{missing}' in {where}") from None
        # The program's module exists, but something it imports does not.
        raise ImportError(f"cannot load program '{reference}': module {module_name} imports '{missing}', which is not installed") from None
    except Exception as error:  # user code may raise anything while importing
        raise ImportError(f"cannot load program '{reference}': {type(error).__name__}: {error}") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        names = [n for n, v in vars(module).items() if inspect.isclass(v) and issubclass(v, Program) and v is not Program]
        raise ImportError(f"cannot load program '{reference}': module {module_name} has no class '{class_name}'{did_you_mean(class_name, names)}")
    if not (inspect.isclass(cls) and issubclass(cls, Program)):
        raise ImportError(f"cannot load program '{reference}': {class_name} is not a softplc Program subclass")
    return cls
