"""What an online change changes: per program, and what would need a restart of the runtime.

Applied online (at a scan boundary, the plant running): a program's code (its module's source, or
the class it names), its `params`, its `bind` (to tags that exist), its `on_fault`, its `restart`
policy, its `enabled`, and the order of the programs in a task.

Refused, because the runtime built them at start and serves them (each with its reason):

- tags and templates: any tag added, removed or changed (type, range, initial, access, unit...):
  OPC UA, Modbus and the HMI serve the tags as declared at start, and the system tags too;
- tasks added, removed or renamed, or a task's interval, priority or watchdog: the scan
  schedule and the `_sys.TASK.*` tags are built from them;
- programs added, removed, renamed or moved to another task (each has its `_sys.TASK.PROGRAM.*`
  tags), and program keys owned by adapters (read by them at start);
- every other section (`servers`, `fleet`, `runtime`, `plant`...): adapters read them at start.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from softplc.config.plant import PlantConfig, ProgramConfig
from softplc.util.durations import format_duration

CORE_KEYS = ("version", "templates", "tags", "tasks")
_TAG_FIELDS = ("type", "initial", "unit", "description", "access", "min", "max", "retain", "group", "options")


@dataclass
class ProgramChange:
    """One program's changes, in words, and which of them need a new program object."""

    name: str
    task: str
    changes: list[str] = field(default_factory=list)
    code: bool = False  # its module's source or its class changed
    params: bool = False
    bind: bool = False
    started: bool = False  # enabled: false → true
    stopped: bool = False  # enabled: true → false
    options_changed: list[str] = field(default_factory=list)  # program keys owned by adapters (need a restart)

    @property
    def new_program(self) -> bool:
        """Whether the change needs a new program object (setup() and carry_over); else it is changed in place."""
        return self.code or self.params or self.bind or self.started


@dataclass
class ConfigDiff:
    """Every difference between the running configuration and the file, sorted into applicable and refused."""

    programs: list[ProgramChange] = field(default_factory=list)
    reordered: list[str] = field(default_factory=list)  # tasks whose programs run in a new order
    needs_restart: list[str] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        return not (self.programs or self.reordered or self.needs_restart)

    def lines(self) -> list[str]:
        """The differences as the engineer reads them."""
        result = [f"program {change.name}: {text}" for change in self.programs for text in change.changes]
        result += [f"task {task}: programs run in a new order" for task in self.reordered]
        result += [f"needs a restart: {reason}" for reason in self.needs_restart]
        return result


def diff_configs(old: PlantConfig, new: PlantConfig, old_code: dict[str, str], new_code: dict[str, str]) -> ConfigDiff:
    """The differences from `old` to `new`; `*_code` map each program to a digest of its module's source."""
    diff = ConfigDiff()
    diff.needs_restart += _tag_changes(old, new)
    diff.needs_restart += _section_changes(old, new)
    old_tasks = {task.name: task for task in old.tasks}
    new_tasks = {task.name: task for task in new.tasks}
    for name in old_tasks.keys() - new_tasks.keys():
        diff.needs_restart.append(f"task '{name}' removed")
    for name in new_tasks.keys() - old_tasks.keys():
        diff.needs_restart.append(f"task '{name}' added")
    old_programs = {program.name: (task.name, program) for task in old.tasks for program in task.programs}
    new_programs = {program.name: (task.name, program) for task in new.tasks for program in task.programs}
    for name, (task, _) in old_programs.items():
        if name not in new_programs:
            diff.needs_restart.append(f"program '{name}' removed from task '{task}' (or renamed)")
    for name, (task, _) in new_programs.items():
        if name not in old_programs:
            diff.needs_restart.append(f"program '{name}' added to task '{task}' (or renamed)")
        elif old_programs[name][0] != task:
            diff.needs_restart.append(f"program '{name}' moved from task '{old_programs[name][0]}' to '{task}'")
    for name in sorted(old_tasks.keys() & new_tasks.keys()):
        before, after = old_tasks[name], new_tasks[name]
        if before.interval != after.interval:
            diff.needs_restart.append(f"task '{name}': interval {format_duration(before.interval)} → {format_duration(after.interval)}")
        follows = before.watchdog == before.interval and after.watchdog == after.interval  # the default: said once
        if before.watchdog != after.watchdog and not follows:
            diff.needs_restart.append(f"task '{name}': watchdog {format_duration(before.watchdog)} → {format_duration(after.watchdog)}")
        if before.priority != after.priority:
            diff.needs_restart.append(f"task '{name}': priority {before.priority} → {after.priority}")
        kept = [p.name for p in before.programs if p.name in {q.name for q in after.programs}]
        if kept != [p.name for p in after.programs if p.name in set(kept)]:
            diff.reordered.append(name)
    for name, (task, program) in new_programs.items():
        if name in old_programs and old_programs[name][0] == task:
            change = _program_change(task, old_programs[name][1], program, old_code.get(name, ""), new_code.get(name, ""))
            if change.options_changed:
                diff.needs_restart.append(f"program '{name}': {', '.join(change.options_changed)} (read by adapters at start)")
            if change.changes:
                diff.programs.append(change)
    return diff


def _program_change(task: str, old: ProgramConfig, new: ProgramConfig, old_code: str, new_code: str) -> ProgramChange:
    change = ProgramChange(new.name, task)
    change.options_changed = sorted(key for key in old.options.keys() | new.options.keys() if old.options.get(key) != new.options.get(key))
    if old.reference != new.reference:
        change.code = True
        change.changes.append(f"program {old.reference} → {new.reference}")
    elif old_code != new_code:
        change.code = True
        change.changes.append(f"code of {new.reference.rpartition(':')[0] or new.reference} changed")
    for key in sorted(old.params.keys() | new.params.keys()):
        if old.params.get(key, "(default)") != new.params.get(key, "(default)"):
            change.params = True
            change.changes.append(f"params: {key} {old.params.get(key, '(default)')!r} → {new.params.get(key, '(default)')!r}")
    for var in sorted(old.bindings.keys() | new.bindings.keys()):
        if old.bindings.get(var) != new.bindings.get(var):
            change.bind = True
            change.changes.append(f"bind: {var} {_shown(old.bindings.get(var))} → {_shown(new.bindings.get(var))}")
    if old.on_fault != new.on_fault:
        change.changes.append(f"on_fault: {old.on_fault.describe()} → {new.on_fault.describe()}")
    if old.restart != new.restart:
        change.changes.append(f"restart: {old.restart.describe()} → {new.restart.describe()}")
    if old.enabled != new.enabled:
        change.started, change.stopped = new.enabled, not new.enabled
        change.changes.append(f"enabled: {str(old.enabled).lower()} → {str(new.enabled).lower()}")
    return change


def _shown(binding: Any) -> str:
    return "(unbound)" if binding is None else str(binding)


def _tag_changes(old: PlantConfig, new: PlantConfig) -> list[str]:
    before = {tag.name: tag for tag in [*old.tags, *old.contributed_tags]}
    after = {tag.name: tag for tag in [*new.tags, *new.contributed_tags]}
    reasons = [f"tag '{name}' removed" for name in before if name not in after]
    reasons += [f"tag '{name}' added" for name in after if name not in before]
    for name in before.keys() & after.keys():
        a, b = before[name], after[name]
        for what in _TAG_FIELDS:
            x, y = getattr(a, what), getattr(b, what)
            if x != y or type(x) is not type(y):
                shown = (x.value, y.value) if what in ("type", "access") else (x, y)
                reasons.append(f"tag '{name}': {what} {shown[0]!r} → {shown[1]!r}")
    if old.shared_outputs != new.shared_outputs:
        for name in sorted(old.shared_outputs ^ new.shared_outputs):
            before, after = (str(name in config.shared_outputs).lower() for config in (old, new))
            reasons.append(f"tag '{name}': shared_output {before} → {after}")
    return sorted(reasons)


def _section_changes(old: PlantConfig, new: PlantConfig) -> list[str]:
    keys = (old.raw.keys() | new.raw.keys()) - set(CORE_KEYS)
    return [f"section '{key}' changed" for key in sorted(keys) if old.raw.get(key) != new.raw.get(key)]
