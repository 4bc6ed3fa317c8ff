"""The problems found in one configuration file: said once each, and once per template mistake.

A template's tags and a `for_each` program are checked once per instance, so one mistake in
them would print once per instance. Problems found for an instance are therefore grouped: those
at the same place become one message that writes the instance as `{template}` and lists the
instances (`'{robot}_load' ... (instances r01, r02 of template 'robot')`); a problem found for
one instance only names that instance.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from softplc.config.yamlsource import Location, Problem, SourceMap

SHOWN_INSTANCES = 6  # instances listed in a grouped message before "and N more"
_QUOTED = re.compile(r"'[^']*'")


class Findings:
    """Collects the problems of one file, with the paths the schema already explained."""

    def __init__(self, source: SourceMap) -> None:
        self.source = source
        self.schema_paths: set[tuple[Any, ...]] = set()
        self._problems: list[Problem] = []
        # (template, location) → [(instance, message)], merged by problems()
        self._by_instance: dict[tuple[str, Location], list[tuple[str, str]]] = {}
        self.instance_counts: dict[str, int] = {}  # template → how many instances it has

    def add(self, problem: Problem, instance: tuple[str, str] | None = None) -> None:
        """Record a problem; `instance` is (template, instance) when it was found for one instance."""
        if instance is None:
            self._problems.append(problem)
        else:
            self._by_instance.setdefault((instance[0], problem.location), []).append((instance[1], problem.message))

    def problem(self, path: Sequence[Any], message: str, *, at_key: bool = False, instance: tuple[str, str] | None = None) -> None:
        """A problem at `path` of the file, unless the schema already explained what is wrong there."""
        if tuple(path) in self.schema_paths:
            return
        self.add(self.source.problem(path, message, at_key=at_key), instance)

    def problem_at(self, where: Sequence[Any] | Location, message: str, *, instance: tuple[str, str] | None = None) -> None:
        """A problem at a path of this file, or at a location in another file (instances_from)."""
        if isinstance(where, Location):
            self.add(Problem(where, message), instance)
        else:
            self.problem(where, message, instance=instance)

    def under_schema_problem(self, path: Sequence[Any]) -> bool:
        """True when the schema reported something at or below `path`."""
        path = tuple(path)
        return any(reported[: len(path)] == path for reported in self.schema_paths)

    def __bool__(self) -> bool:
        return bool(self._problems or self._by_instance)

    def problems(self) -> list[Problem]:
        """Every problem, those found per instance grouped by place."""
        result = list(self._problems)
        for (template, location), found in self._by_instance.items():
            instances = list(dict.fromkeys(instance for instance, _ in found))
            if len(instances) == 1:
                result.extend(Problem(location, message) for _, message in found)
                continue
            general = list(dict.fromkeys(_generalize(message, instance, template) for instance, message in found))
            shown = ", ".join(instances[:SHOWN_INSTANCES]) + (f" and {len(instances) - SHOWN_INSTANCES} more" if len(instances) > SHOWN_INSTANCES else "")
            which = "every instance" if len(instances) == self.instance_counts.get(template) else "instances"
            for message in general:
                mentions = "{" + template + "}" in message
                result.append(Problem(location, f"{message} ({which} of template '{template}': {shown})" if mentions else message))
        return result


def _generalize(message: str, instance: str, template: str) -> str:
    """`message` with the instance's name written `{template}` inside its quoted names."""
    name = re.compile(rf"(?<![A-Za-z0-9]){re.escape(instance)}(?![A-Za-z0-9])")
    return _QUOTED.sub(lambda quoted: name.sub("{" + template + "}", quoted.group(0)), message)
