"""A program's `on_fault:` (what its outputs do when it faults) and `restart:` (whether it restarts by itself).

    on_fault: hold | initial | {safe: {TAG: VALUE}, others: hold|initial}      (default hold)
    restart: never | {delay: 1s, max: 3}                                       (default never)

Before issue 17, `on_fault: stop|restart` with `restart_delay` and `max_restarts` was the restart
policy. That form is a located problem saying what to write instead, reported once per program
and instead of the schema's "unknown value"/"unknown key" messages.
"""

from __future__ import annotations

from typing import Any

from softplc.config.findings import Findings
from softplc.config.programs import Write, substitute
from softplc.config.tags import TagChecker
from softplc.config.yamlsource import Problem, SourceMap
from softplc.core.datatypes import TypeMismatch
from softplc.core.fault_reaction import HOLD, INITIAL, NEVER, FaultReaction, RestartPolicy
from softplc.util.durations import check_duration
from softplc.util.suggest import did_you_mean

LEGACY_KEYS = ("restart_delay", "max_restarts")
LEGACY_ON_FAULT = ("stop", "restart")


def legacy_problems(data: Any, source: SourceMap) -> tuple[list[Problem], set[tuple[Any, ...]]]:
    """The old restart policy in any program, one problem each, and the paths they explain."""
    problems: list[Problem] = []
    explained: set[tuple[Any, ...]] = set()
    tasks = data.get("tasks") if isinstance(data, dict) else None
    for task_name, task in (tasks or {}).items() if isinstance(tasks, dict) else ():
        programs = task.get("programs") if isinstance(task, dict) else None
        for index, spec in enumerate(programs if isinstance(programs, list) else []):
            path = ("tasks", task_name, "programs", index)
            old = _legacy_keys(spec)
            if not old:
                continue
            explained.update((*path, key) for key in old)
            first = min(old, key=lambda key: source.key((*path, key)))
            problems.append(source.problem((*path, first), _legacy_message(spec, old), at_key=True))
    return problems, explained


def _legacy_keys(spec: Any) -> list[str]:
    if not isinstance(spec, dict):
        return []
    keys = [key for key in LEGACY_KEYS if key in spec]
    if spec.get("on_fault") in LEGACY_ON_FAULT:
        keys.insert(0, "on_fault")
    return keys


def _legacy_message(spec: dict[str, Any], old: list[str]) -> str:
    written = ", ".join(f"{key}: {_yaml(spec[key])}" for key in old)
    outputs = "on_fault: now says what the program's outputs do when it faults (hold, initial or safe: {TAG: value})"
    if spec.get("on_fault") == "restart":
        delay = _yaml(spec.get("restart_delay", "1s"))
        maximum = _yaml(spec.get("max_restarts", 3))
        return f"'{written}' is the old restart policy: write restart: {{delay: {delay}, max: {maximum}}} instead; {outputs}"
    if spec.get("on_fault") == "stop" and len(old) == 1:
        return (f"'{written}' is the old restart policy: remove it (a faulted program stays FAULTED unless it says "
                f"restart: {{delay: 1s, max: 3}}); {outputs}")
    return (f"'{written}' belongs to the old restart policy (and never restarted this program without on_fault: restart): "
            "remove it, or write restart: {delay: 1s, max: 3} to restart the program after a fault; " + outputs)


def _yaml(value: Any) -> str:
    return str(value).lower() if isinstance(value, bool) else str(value)


def is_legacy(spec: Any) -> bool:
    return bool(_legacy_keys(spec))


def restart_policy(findings: Findings, spec: dict[str, Any], path: tuple[Any, ...]) -> RestartPolicy:
    """The program's `restart:` (the schema has checked its shape)."""
    value = spec.get("restart", "never")
    if not isinstance(value, dict):
        return NEVER
    delay = 1.0
    if "delay" in value:
        seconds, message = check_duration(value["delay"], "restart delay")
        if message:
            findings.problem((*path, "restart", "delay"), message)
        delay = seconds if seconds is not None else delay
    maximum = value.get("max", 3)
    return RestartPolicy(True, delay, maximum if isinstance(maximum, int) and not isinstance(maximum, bool) else 3)


def reaction_shape(spec: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """(others, the raw safe values) of a program's `on_fault:` (the schema has checked its shape)."""
    value = spec.get("on_fault", HOLD)
    if is_legacy(spec) or value is None:
        return HOLD, {}
    if isinstance(value, str):
        return (value if value in (HOLD, INITIAL) else HOLD), {}
    if isinstance(value, dict):
        others = value.get("others", HOLD)
        safe = value.get("safe")
        return (others if others in (HOLD, INITIAL) else HOLD), (safe if isinstance(safe, dict) else {})
    return HOLD, {}


def fault_reaction(
    findings: Findings, tags: TagChecker, spec: dict[str, Any], path: tuple[Any, ...], name: str,
    substitution: dict[str, str], writes: list[Write], instance: tuple[str, str] | None,
) -> FaultReaction | None:
    """One program instance's reaction, its safe values checked against the tags it writes (None if wrong)."""
    others, raw = reaction_shape(spec)
    written = {write.tag: write for write in writes if write.program == name}
    safe: dict[str, Any] = {}
    ok = True
    for key, value in raw.items():
        where = (*path, "on_fault", "safe", key)
        tag = substitute(str(key), substitution)
        definition = tags.tags.get(tag)
        if definition is None:
            if not tags.knows(tag):  # a tag declared wrongly was reported where it is declared
                findings.problem(where, f"'{tag}' in on_fault: safe of program '{name}' is not a tag{did_you_mean(tag, tags.tags)}",
                                 at_key=True, instance=instance)
            ok = False
            continue
        if tag not in written:
            outputs = ", ".join(f"{w.variable} → {t}" for t, w in written.items()) or "none"
            findings.problem(where, f"'{tag}' in on_fault: safe is not an output of program '{name}': a fault reaction sets only "
                             f"the tags the program writes (its Output and InOut variables: {outputs})", at_key=True, instance=instance)
            ok = False
            continue
        message = _value_problem(definition, value)
        if message:
            shown = f"'{value}'" if isinstance(value, str) else _yaml(value)
            findings.problem(where, f"safe value {shown} of '{tag}' {message}", instance=instance)
            ok = False
            continue
        safe[tag] = definition.type.coerce(value)
    return FaultReaction(safe, others) if ok else None


def _value_problem(definition: Any, value: Any) -> str:
    """Why `value` cannot be the tag's value ('' when it can): its type, then its range."""
    try:
        coerced = definition.type.coerce(value)
    except TypeMismatch as error:
        return f"does not fit its type {definition.type.value}: {error}"
    if definition.min is not None or definition.max is not None:
        if coerced != coerced:
            return "is NaN, which is outside the range of a bounded tag"
        if definition.min is not None and coerced < definition.min:
            return f"is below its min {definition.min}"
        if definition.max is not None and coerced > definition.max:
            return f"is above its max {definition.max}"
    return ""
