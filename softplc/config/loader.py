"""Load a configuration file: structure (JSON Schema), tags, tasks, outputs, then every owner's section.

Every mistake becomes a `Problem` with `FILE:LINE:COL`; all problems of a file are reported
together by raising `ConfigError`. Nothing here starts anything.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from softplc.config.findings import Findings
from softplc.config.outputs import check_outputs
from softplc.config.plant import PlantConfig
from softplc.config.programs import ModuleLoader, ProgramChecker
from softplc.config.reactions import legacy_problems
from softplc.config.schema_check import describe, schema_check
from softplc.config.sections import config_schema, contributed_tags, section_problems
from softplc.config.tags import TagChecker
from softplc.config.tasks import TaskChecker
from softplc.config.yamlsource import ConfigError, SourceMap, load_yaml, parse_yaml


def load_config(path: str | Path, *, load_module: ModuleLoader | None = None) -> PlantConfig:
    """Load and check a configuration file; raise ConfigError listing every problem.

    `load_module` loads the program modules (default: the usual, cached import; see `import_program`).
    """
    path = Path(path)
    data, source = load_yaml(path)
    return check_config(path, data, source, load_module=load_module)


def parse_config(text: str, path: str | Path = "<string>") -> PlantConfig:
    """Check configuration text as if read from `path` (programs resolve relative to it)."""
    data, source = parse_yaml(text, str(path))
    return check_config(Path(path), data, source)


def check_config(path: Path, data: Any, source: SourceMap, *, load_module: ModuleLoader | None = None) -> PlantConfig:
    """The checked plant of parsed YAML `data`; raise ConfigError listing every problem."""
    if data is None:
        raise ConfigError([source.problem((), "the file is empty: expected a plant configuration (version, tags, tasks...)")])
    if not isinstance(data, dict):
        raise ConfigError([source.problem((), f"the file must be a mapping of sections, not {describe(data)}")])
    findings = Findings(source)
    # An old form of a key (the restart policy before issue 17) is said once, with what to write
    # instead, rather than as the schema's "unknown key" or "unknown value".
    legacy, explained = legacy_problems(data, source)
    for problem in legacy:
        findings.add(problem)
    problems, findings.schema_paths = schema_check(data, source, config_schema(), explained)
    for problem in problems:
        findings.add(problem)
    # The core's checks run on whatever is well-formed, so one pass reports as much as possible;
    # what the schema already reported is not said again.
    tags = TagChecker(findings, path.parent)
    tags.check(data)
    tasks = TaskChecker(findings, tags, ProgramChecker(findings, tags, path.parent, load_module))
    task_configs = tasks.check(data.get("tasks"))
    check_outputs(findings, tasks.writes, tags.shared_outputs)
    if findings:
        raise ConfigError(findings.problems())
    plant = data.get("plant") or {}
    config = PlantConfig(
        path=path,
        name=plant.get("name", path.stem),
        description=plant.get("description", ""),
        tags=list(tags.tags.values()),
        instances=tags.instances,
        tasks=task_configs,
        servers=data.get("servers") or {},
        runtime=data.get("runtime") or {},
        raw=data,
        source=source,
        tag_paths=dict(tags.tag_paths),
        shared_outputs=set(tags.shared_outputs),
    )
    config.contributed_tags = contributed_tags(config)
    # The owners of the other sections check what their schema cannot say, on a plant whose
    # core is sound (so none of them reports a follow-on of a core mistake).
    problems = section_problems(config)
    if problems:
        raise ConfigError(problems)
    return config
