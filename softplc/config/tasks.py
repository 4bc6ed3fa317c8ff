"""Tasks and the programs they scan: intervals, watchdogs, priorities, `for_each`, fault reactions and restart policies."""

from __future__ import annotations

from typing import Any

from softplc.config.findings import Findings
from softplc.config.plant import ProgramConfig, TaskConfig
from softplc.config.programs import ProgramChecker, Write, substitute
from softplc.config.reactions import fault_reaction, restart_policy
from softplc.config.sections import program_keys
from softplc.config.tags import TagChecker
from softplc.util.durations import check_duration
from softplc.util.suggest import did_you_mean

SHORTEST_INTERVAL = 1e-4


class TaskChecker:
    """Builds the tasks and their program instances, recording every problem."""

    def __init__(self, findings: Findings, tags: TagChecker, programs: ProgramChecker) -> None:
        self.findings = findings
        self.tags = tags
        self.programs = programs
        self.writes: list[Write] = []  # every tag an enabled program writes, in scan order

    def _duration(self, value: Any, path: tuple[Any, ...], what: str) -> float | None:
        seconds, message = check_duration(value, what)
        if message:
            self.findings.problem(path, message)
        return seconds

    def check(self, tasks: Any) -> list[TaskConfig]:
        result: list[TaskConfig] = []
        if not isinstance(tasks, dict):
            return result
        program_names: dict[str, tuple[Any, ...]] = {}
        for task_name, task in tasks.items():
            base = ("tasks", task_name)
            if not isinstance(task, dict):
                continue
            interval = self._duration(task.get("interval"), (*base, "interval"), "interval") if "interval" in task else None
            if interval is not None and interval < SHORTEST_INTERVAL:
                self.findings.problem((*base, "interval"), f"bad interval {task['interval']!r}: the shortest supported interval is 100us")
                interval = None
            watchdog = None
            if "watchdog" in task:
                watchdog = self._duration(task["watchdog"], (*base, "watchdog"), "watchdog")
            programs: list[ProgramConfig] = []
            for index, spec in enumerate(task.get("programs") or []):
                for program, writes in self._check_program(spec, (*base, "programs", index)):
                    if program.name in program_names:
                        first = self.findings.source.value(program_names[program.name])
                        self.findings.problem((*base, "programs", index, "name"), f"duplicate program name '{program.name}' (also used at {first})")
                        continue
                    program_names[program.name] = (*base, "programs", index, "name")
                    programs.append(program)
                    if program.enabled:  # a disabled program never writes
                        self.writes.extend(writes)
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

    def _check_program(self, spec: Any, path: tuple[Any, ...]) -> list[tuple[ProgramConfig, list[Write]]]:
        """The program instances of one `programs:` item (one per instance with for_each)."""
        if not isinstance(spec, dict) or not isinstance(spec.get("program"), str) or not isinstance(spec.get("name"), str):
            return []
        cls = self.programs.import_class(spec["program"], (*path, "program"))
        for_each = spec.get("for_each")
        instances = self.tags.instances
        if for_each is None:
            substitutions: list[dict[str, str]] = [{}]
        elif isinstance(for_each, str) and for_each in instances:
            substitutions = [{for_each: instance} for instance in instances[for_each]]
        else:
            if self.tags.names_known:  # else the template may be one whose mistake hid it
                self.findings.problem((*path, "for_each"), f"for_each must name a template; '{for_each}' is not one{did_you_mean(str(for_each), instances)}")
            return []
        if for_each is not None and "{" + for_each + "}" not in spec["name"]:
            self.findings.problem((*path, "name"), f"with for_each: {for_each}, the name must contain {{{for_each}}} so each instance is unique")
            return []
        restart = restart_policy(self.findings, spec, path)
        location = self.findings.source.value((*path, "program"))
        options = {key: spec[key] for key in program_keys() if key in spec}
        results = []
        for substitution in substitutions:
            name = substitute(spec["name"], substitution)
            instance = (for_each, substitution[for_each]) if for_each is not None else None
            bindings, writes = self.programs.bindings(cls, spec.get("bind") or {}, substitution, path, name, instance)
            params = self.programs.params(cls, spec.get("params") or {}, substitution, path, name, instance)
            if cls is None or bindings is None or params is None:
                continue
            reaction = fault_reaction(self.findings, self.tags, spec, path, name, substitution, writes, instance)
            if reaction is None:
                continue
            program = ProgramConfig(name, spec["program"], cls, bindings, params, restart, bool(spec.get("enabled", True)), location,
                                    dict(options), reaction, path)
            results.append((program, writes))
        return results
