"""YAML loading that remembers where every key and value came from (file, line, column).

`load_yaml(path)` returns the plain Python data plus a `SourceMap` that answers "where is the
value at path ('tasks', 'fast', 'interval')?", so configuration errors can say
`tagdb.yaml:42:15: bad interval ...` instead of raising a traceback.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

Path_ = tuple[str | int, ...]


@dataclass(frozen=True, order=True)
class Location:
    file: str
    line: int  # 1-based
    column: int  # 1-based

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"


@dataclass(frozen=True, order=True)
class Problem:
    """One configuration mistake, with its location."""

    location: Location
    message: str

    def __str__(self) -> str:
        return f"{self.location}: {self.message}"


class ConfigError(Exception):
    """A configuration has one or more problems; `problems` lists them all."""

    def __init__(self, problems: Sequence[Problem]) -> None:
        self.problems = sorted(set(problems))  # the same mistake found twice is said once
        super().__init__("\n".join(str(problem) for problem in self.problems))


@dataclass
class SourceMap:
    """Locations of keys and values by their path in the document."""

    file: str
    values: dict[Path_, Location] = field(default_factory=dict)
    keys: dict[Path_, Location] = field(default_factory=dict)

    def value(self, path: Sequence[str | int]) -> Location:
        """Where the value at `path` is; falls back to the nearest enclosing node."""
        path = tuple(path)
        while path not in self.values and path:
            path = path[:-1]
        return self.values.get(path, Location(self.file, 1, 1))

    def key(self, path: Sequence[str | int]) -> Location:
        """Where the key that ends `path` is written (for 'unknown key' errors)."""
        path = tuple(path)
        return self.keys.get(path) or self.value(path)

    def problem(self, path: Sequence[str | int], message: str, *, at_key: bool = False) -> Problem:
        return Problem(self.key(path) if at_key else self.value(path), message)


def _location(file: str, mark: yaml.Mark) -> Location:
    return Location(file, mark.line + 1, mark.column + 1)


class _Builder:
    def __init__(self, file: str) -> None:
        self.map = SourceMap(file)
        self.problems: list[Problem] = []
        self._constructor = yaml.SafeLoader("")  # only used to turn scalar nodes into values

    def build(self, node: yaml.Node, path: Path_) -> Any:
        file = self.map.file
        self.map.values[path] = _location(file, node.start_mark)
        if isinstance(node, yaml.MappingNode):
            self._constructor.flatten_mapping(node)
            result: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                key = self._constructor.construct_object(key_node, deep=True)
                if not isinstance(key, (str, int, float, bool)) or key is None:
                    self.problems.append(Problem(_location(file, key_node.start_mark), "a key must be a plain name"))
                    continue
                key = str(key) if not isinstance(key, str) else key
                child = (*path, key)
                if key in result:
                    first = self.map.keys[child]
                    self.problems.append(
                        Problem(_location(file, key_node.start_mark), f"duplicate key '{key}' (first defined at line {first.line})")
                    )
                    continue
                self.map.keys[child] = _location(file, key_node.start_mark)
                result[key] = self.build(value_node, child)
            return result
        if isinstance(node, yaml.SequenceNode):
            return [self.build(item, (*path, index)) for index, item in enumerate(node.value)]
        return self._constructor.construct_object(node, deep=True)


def load_yaml(path: str | Path) -> tuple[Any, SourceMap]:
    """Parse a YAML file; raise ConfigError (never a YAML traceback) on syntax errors."""
    path = Path(path)
    file = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError([Problem(Location(file, 1, 1), "file not found")]) from None
    except (OSError, UnicodeDecodeError) as error:
        raise ConfigError([Problem(Location(file, 1, 1), f"cannot read the file: {error}")]) from None
    return parse_yaml(text, file)


def _indenting_tab(text: str, line_index: int) -> tuple[int, int] | None:
    """(line, column), 1-based, of a tab in the indentation of line `line_index` (0-based), or None."""
    lines = text.splitlines()
    if not 0 <= line_index < len(lines):
        return None
    line = lines[line_index]
    indentation = line[: len(line) - len(line.lstrip(" \t"))]
    return (line_index + 1, indentation.index("\t") + 1) if "\t" in indentation else None


# libyaml (PyYAML's C parser) composes the same nodes, marks and styles as the pure-Python one
# (tests/config/test_yaml_source.py compares them for every YAML file of the repository) in a
# tenth of the time: 0.2 s of every start of the default plant before. Its error messages are
# its own, so a text it refuses is parsed again by the Python parser, whose messages we explain.
_FAST_LOADER = getattr(yaml, "CSafeLoader", None)


def _compose(text: str) -> yaml.Node | None:
    if _FAST_LOADER is not None:
        try:
            return yaml.compose(text, Loader=_FAST_LOADER)
        except yaml.YAMLError:
            pass
    return yaml.compose(text, Loader=yaml.SafeLoader)


def parse_yaml(text: str, file: str = "<string>") -> tuple[Any, SourceMap]:
    """Parse YAML text (see `load_yaml`)."""
    try:
        node = _compose(text)
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        tab = _indenting_tab(text, mark.line) if mark else None
        if tab is not None or "'\\t'" in (error.problem or ""):
            # PyYAML's words ("found character '\\t' that cannot start any token") name no cure.
            line, column = tab if tab is not None else (mark.line + 1, mark.column + 1)
            raise ConfigError([Problem(Location(file, line, column), "tabs are not allowed for indentation; use spaces")]) from None
        location = _location(file, mark) if mark else Location(file, 1, 1)
        message = error.problem or str(error)
        if error.context:
            message = f"{error.context}: {message}"
        context = error.context_mark
        if context is not None and mark is not None and context.line != mark.line:
            # The mistake is often where the construct began (an unclosed '{' or quote).
            message += f" (the construct began at line {context.line + 1}, column {context.column + 1})"
        raise ConfigError([Problem(location, f"YAML syntax error: {message}")]) from None
    except yaml.YAMLError as error:
        raise ConfigError([Problem(Location(file, 1, 1), f"YAML error: {error}")]) from None
    builder = _Builder(file)
    if node is None:
        return None, builder.map
    try:
        data = builder.build(node, ())
    except yaml.constructor.ConstructorError as error:
        mark = error.problem_mark
        location = _location(file, mark) if mark else Location(file, 1, 1)
        raise ConfigError([Problem(location, f"YAML error: {error.problem}")]) from None
    if builder.problems:
        raise ConfigError(builder.problems)
    return data, builder.map
