"""What a checked configuration is: the plant's tags, tasks and programs, and its raw sections."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from softplc.config.yamlsource import Location, Problem, SourceMap
from softplc.core.fault_reaction import NEVER, FaultReaction, RestartPolicy
from softplc.core.program import Program
from softplc.core.tags import TagDef

SYSTEM_PREFIX = "_sys."


@dataclass
class ProgramConfig:
    """One program of a task: its class imported, its variables bound to existing tags."""

    name: str
    reference: str
    cls: type[Program]
    bindings: dict[str, str | list[str]]
    params: dict[str, Any]
    restart: RestartPolicy = NEVER
    enabled: bool = True
    location: Location | None = None  # where the program is named in the file (for errors)
    options: dict[str, Any] = field(default_factory=dict)  # keys owners add to programs (softplc.config.sections)
    on_fault: FaultReaction = field(default_factory=FaultReaction)  # what its outputs do when it faults
    path: tuple[Any, ...] = ()  # its item in the file: ("tasks", TASK, "programs", INDEX)


@dataclass
class TaskConfig:
    """A cyclic task: interval, priority and watchdog in seconds, its programs in scan order."""

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
    # Where each tag is declared in the file: ("tags", NAME) or ("templates", T, "tags", NAME).
    tag_paths: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    # Tags the section owners add to the runtime besides the system tags (Section.tags).
    contributed_tags: list[TagDef] = field(default_factory=list)
    # Tags declared `shared_output: true` (several programs may write them).
    shared_outputs: set[str] = field(default_factory=set)

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

    def section(self, *path: str) -> dict[str, Any] | None:
        """The mapping at `path` (e.g. "servers", "modbus"), or None when the file has none."""
        node: Any = self.raw
        for key in path:
            node = node.get(key) if isinstance(node, dict) else None
        return node if isinstance(node, dict) else None

    def option_path(self, tag: str, key: str) -> tuple[Any, ...]:
        """Where the `key` option of a tag is written: in the tag itself, or in its template."""
        path = self.tag_paths.get(tag, ())
        node: Any = self.raw
        for step in path:
            node = node.get(step) if isinstance(node, dict) else None
        if isinstance(node, dict) and key in node or path[:1] != ("templates",):
            return (*path, key)
        return (*path[:2], key)

    def problem(self, path: Sequence[str | int], message: str, *, at_key: bool = False) -> Problem:
        """A Problem located at `path` of this file (its first line when the source is unknown)."""
        if self.source is None:
            return Problem(Location(str(self.path), 1, 1), message)
        return self.source.problem(path, message, at_key=at_key)
