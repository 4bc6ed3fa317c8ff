"""The configuration's YAML parser: libyaml composes what PyYAML's Python parser composes, marks included."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from softplc.config import yamlsource
from softplc.config.yamlsource import ConfigError, parse_yaml

REPO = Path(__file__).resolve().parents[2]
FILES = sorted(path for pattern in ("*.yaml", "scenarios/*.yaml", "robots/**/*.yaml", "programs/*.yaml", "tests/configs/**/*.yaml")
               for path in REPO.glob(pattern))


def _shape(node: yaml.Node | None) -> list[tuple[object, ...]]:
    """Every node of a tree: kind, tag, start and end marks, value of scalars, style."""
    shape: list[tuple[object, ...]] = []
    stack = [node] if node is not None else []
    while stack:
        item = stack.pop()
        start, end = item.start_mark, item.end_mark
        value = item.value if isinstance(item, yaml.ScalarNode) else None
        # PyYAML says None for a plain scalar's style and libyaml says '': the same style.
        shape.append((type(item).__name__, item.tag, start.line, start.column, end.line, end.column, value,
                      getattr(item, "style", None) or None, getattr(item, "flow_style", None)))
        if isinstance(item, yaml.MappingNode):
            stack.extend(child for pair in reversed(item.value) for child in reversed(pair))
        elif isinstance(item, yaml.SequenceNode):
            stack.extend(reversed(item.value))
    return shape


def test_the_fast_parser_is_there() -> None:
    assert yamlsource._FAST_LOADER is not None, "PyYAML without libyaml: every start parses YAML ten times slower"


@pytest.mark.parametrize("path", FILES, ids=lambda path: str(path.relative_to(REPO)))
def test_libyaml_and_the_python_parser_compose_the_same_nodes(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    try:
        expected = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        with pytest.raises(yaml.YAMLError):
            yaml.compose(text, Loader=yaml.CSafeLoader)
        return
    assert _shape(yaml.compose(text, Loader=yaml.CSafeLoader)) == _shape(expected)


def test_marks_count_characters_beyond_ascii_alike() -> None:
    text = 'a: {é€😀: 1, x: 2}\n"ü": [1, ☃, y]\nb: |\n  ää\nc: 3\n'
    assert _shape(yaml.compose(text, Loader=yaml.CSafeLoader)) == _shape(yaml.compose(text, Loader=yaml.SafeLoader))


def test_a_syntax_error_keeps_the_python_parsers_explained_message() -> None:
    with pytest.raises(ConfigError) as raised:
        parse_yaml("tags:\n\tx: {type: bool}\n", "plant.yaml")
    assert "plant.yaml:2:1: tabs are not allowed for indentation; use spaces" in str(raised.value)
    with pytest.raises(ConfigError) as raised:
        parse_yaml("tags: {x: [1, 2}\n", "plant.yaml")
    assert "YAML syntax error" in str(raised.value) and "plant.yaml:1:" in str(raised.value)
