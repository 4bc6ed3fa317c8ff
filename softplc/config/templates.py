"""The instances of a template: listed, counted (`r01`..`r12`), or read from another file."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from softplc.config.findings import Findings
from softplc.config.schema import NAME_PATTERN, NAME_RULE
from softplc.config.yamlsource import ConfigError, Location, SourceMap, load_yaml
from softplc.util.suggest import did_you_mean

# template → instance → tag → (initial value, where it is written), from instances_from
ExternalInitials = dict[str, dict[str, tuple[Any, Location]]]


@dataclass
class Instances:
    """A template's instance names; `complete` is False when a reported mistake hid some of them."""

    names: list[str] = field(default_factory=list)
    complete: bool = False
    initials: ExternalInitials = field(default_factory=dict)  # from instances_from


def template_instances(findings: Findings, base_dir: Path, name: str, template: dict[str, Any], base: tuple[Any, ...]) -> Instances:
    """The instances of a template, and the initial values read with them."""
    explicit = template.get("instances")
    count = template.get("count")
    if explicit is not None and count is not None:
        findings.problem((*base, "count"), "give either 'instances' or 'count', not both", at_key=True)
    if "instances_from" in template:
        if explicit is not None or count is not None:
            findings.problem((*base, "instances_from"), "give only one of 'instances', 'count' or 'instances_from'", at_key=True)
        return _instances_from(findings, base_dir, name, template, base)
    if isinstance(explicit, list):
        seen: set[str] = set()
        result = []
        complete = True
        for index, instance in enumerate(explicit):
            if not isinstance(instance, str) or not is_name(instance):
                complete = False  # the schema reported it
                continue
            if instance in seen:
                findings.problem((*base, "instances", index), f"duplicate instance '{instance}'")
                continue
            seen.add(instance)
            result.append(instance)
        return Instances(result, complete)
    if isinstance(count, int) and not isinstance(count, bool) and count >= 1:
        prefix = template.get("prefix", name[:1])
        width = max(2, len(str(count)))
        return Instances([f"{prefix}{index:0{width}d}" for index in range(1, count + 1)], True)
    if explicit is None and count is None and not findings.under_schema_problem(base):  # e.g. 'instance:', already reported
        findings.problem(base, f"template '{name}' needs 'instances' (a list of names) or 'count'", at_key=True)
    return Instances()


def _instances_from(findings: Findings, base_dir: Path, name: str, template: dict[str, Any], base: tuple[Any, ...]) -> Instances:
    """Instance names from the `id` of each item of a YAML list in another file, plus initial values."""
    spec = template["instances_from"]
    where = (*base, "instances_from")
    if isinstance(spec, str):
        spec = {"file": spec}
    elif isinstance(spec, dict) and isinstance(spec.get("file"), str):
        where = (*where, "file")
    else:
        return Instances()  # the schema reported it
    file = base_dir / spec["file"]
    if not file.is_file():
        findings.problem(where, f"instances_from: file not found: {file}")
        return Instances()
    try:
        data, source = load_yaml(file)
    except ConfigError as error:
        for problem in error.problems:
            findings.add(problem)
        return Instances()
    items, prefix = _external_list(findings, data, spec.get("key"), where, file)
    if items is None:
        return Instances()
    result: list[str] = []
    complete = True
    for index, item in enumerate(items):
        item_id = item.get("id") if isinstance(item, dict) else None
        if not isinstance(item_id, str) or not is_name(item_id):
            what = f"its id {item_id!r} is not a valid name ({NAME_RULE})" if item_id is not None else "it has no 'id'"
            findings.add(source.problem((*prefix, index), f"item {index + 1} cannot be an instance of template '{name}': {what}"))
            complete = False
            continue
        if item_id in result:
            findings.add(source.problem((*prefix, index, "id"), f"duplicate id '{item_id}'"))
            continue
        result.append(item_id)
    return Instances(result, complete, _initials_from(findings, source, items, prefix, spec, name, template, base, file, result))


def _initials_from(findings: Findings, source: SourceMap, items: list[Any], prefix: tuple[Any, ...], spec: dict[str, Any], name: str,
                   template: dict[str, Any], base: tuple[Any, ...], file: Path, instances: list[str]) -> ExternalInitials:
    """Initial values `instances_from: {initial: {TAG: dotted.key}}` takes from the items."""
    initial = spec.get("initial") if isinstance(spec.get("initial"), dict) else {}
    tag_specs = template.get("tags") if isinstance(template.get("tags"), dict) else {}
    values: ExternalInitials = {item_id: {} for item_id in instances}
    for tag_name, dotted in initial.items():
        if tag_name not in tag_specs:
            findings.problem((*base, "instances_from", "initial", tag_name), f"template '{name}' has no tag '{tag_name}'{did_you_mean(tag_name, tag_specs)}", at_key=True)
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
            findings.problem((*base, "instances_from", "initial", tag_name), f"no item of {file} has '{dotted}'")
    return values


def _external_list(findings: Findings, data: Any, key: Any, where: tuple[Any, ...], file: Path) -> tuple[list[Any] | None, tuple[Any, ...]]:
    """The list of items in an instances_from file: the file itself, or its (only) list entry."""
    if isinstance(key, str):
        if isinstance(data, dict) and isinstance(data.get(key), list):
            return data[key], (key,)
        findings.problem(where, f"instances_from: {file} has no list under '{key}'")
        return None, ()
    if isinstance(data, list):
        return data, ()
    lists = [k for k, v in data.items() if isinstance(v, list)] if isinstance(data, dict) else []
    if len(lists) == 1:
        return data[lists[0]], (lists[0],)
    found = f"several lists ({', '.join(lists)}): name one with 'key'" if lists else "no list of items with 'id'"
    findings.problem(where, f"instances_from: {file} has {found}")
    return None, ()


def is_name(text: str) -> bool:
    """A valid tag, template, instance or task name."""
    return re.match(NAME_PATTERN, text) is not None
