"""JSON Schema violations as located messages a user understands ("unknown key 'unti' (did you mean 'unit'?)")."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.config.schema import NAME_RULE
from softplc.config.yamlsource import Problem, SourceMap
from softplc.util.suggest import did_you_mean

if TYPE_CHECKING:
    import jsonschema


def describe(value: Any) -> str:
    """A value as a message names it: "string 'x'", "number 3", "a list"."""
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


RESERVED_TAG_PREFIX = "_sys"  # system tags' names (softplc/config/tags.py refuses '_sys_x' the same way)


def _names_a_tag(path: tuple[Any, ...] | list[Any]) -> bool:
    """Whether `path` is a tag's key: tags.NAME or templates.T.tags.NAME."""
    path = tuple(path)
    return (len(path) == 2 and path[0] == "tags") or (len(path) == 4 and path[0] == "templates" and path[2] == "tags")


_TYPE_WORDS = {"object": "a mapping", "array": "a list", "string": "a string", "number": "a number",
               "integer": "an integer", "boolean": "true or false", "null": "null"}


def schema_problems(data: Any, source: SourceMap, schema: dict[str, Any]) -> list[Problem]:
    """Check `data` against a JSON Schema; each violation becomes a located, readable Problem."""
    return schema_check(data, source, schema)[0]


def schema_check(
    data: Any, source: SourceMap, schema: dict[str, Any], explained: set[tuple[Any, ...]] | None = None,
) -> tuple[list[Problem], set[tuple[Any, ...]]]:
    """The schema's problems, and the paths they are about (semantic checks skip those).

    `explained`: paths another check has already reported better (an old form of a key, with what
    to write instead); the schema says nothing at or below them.
    """
    import jsonschema  # ~60 ms to import: only commands that load a configuration pay for it

    explained = explained or set()
    validator = jsonschema.Draft202012Validator(schema)
    problems: list[Problem] = []
    paths: set[tuple[Any, ...]] = set()
    for error in validator.iter_errors(data):
        path = tuple(error.absolute_path)
        if "propertyNames" in error.absolute_schema_path:
            path = (*path, error.instance)  # the error is about a key: point at that key
        if any(path[: len(done)] == done for done in explained):
            continue
        if error.validator == "additionalProperties" and isinstance(error.instance, dict):
            known = error.schema.get("properties", {})
            unknown = [key for key in error.instance if key not in known and (*path, key) not in explained]
            if not unknown:
                continue
            paths.update((*path, key) for key in unknown)
        else:
            paths.add(path)
        problems.extend(_translate(error, path, source, explained))
    return problems, paths


def _translate(error: jsonschema.ValidationError, path: tuple[Any, ...], source: SourceMap, explained: set[tuple[Any, ...]]) -> list[Problem]:
    kind = error.validator
    if not path:
        where = "the file"
    elif isinstance(path[-1], int):  # a list item: name the list, not the index
        where = f"item {path[-1] + 1} of '{path[-2]}'" if len(path) > 1 else f"item {path[-1] + 1}"
    else:
        where = f"'{path[-1]}'"
    if kind == "additionalProperties":
        known = list(error.schema.get("properties", {}))
        unknown = [key for key in error.instance if key not in known and (*path, key) not in explained]
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
        shown = f"'{value}'" if isinstance(value, str) else describe(value)
        what = f"type {shown}" if path and path[-1] == "type" else f"value {shown} for {where}"
        hint = did_you_mean(str(value), choices)
        return [source.problem(path, f"unknown {what}{hint}; expected one of: {', '.join(choices)}")]
    if kind == "type":
        expected = error.validator_value
        expected_words = " or ".join(_TYPE_WORDS.get(t, t) for t in ([expected] if isinstance(expected, str) else expected))
        return [source.problem(path, f"{where} must be {expected_words}, not {describe(error.instance)}")]
    if kind == "pattern":
        is_key = "propertyNames" in error.absolute_schema_path
        if is_key and _names_a_tag(path) and str(error.instance).startswith(RESERVED_TAG_PREFIX):
            # '_sys.state' is a system tag's very name: reserved, as '_sys_state' is (softplc/config/tags.py).
            return [source.problem(path, f"tag names starting with '{RESERVED_TAG_PREFIX}' are reserved for system tags: '{error.instance}'", at_key=True)]
        return [source.problem(path, f"invalid name '{error.instance}' ({NAME_RULE})", at_key=is_key)]
    if kind == "const":
        return [source.problem(path, f"{where} must be {error.validator_value!r}, not {describe(error.instance)}")]
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        relation = {"minimum": "at least", "maximum": "at most", "exclusiveMinimum": "more than", "exclusiveMaximum": "less than"}[kind]
        return [source.problem(path, f"{where} must be {relation} {error.validator_value}, not {error.instance}")]
    return [source.problem(path, f"{where}: {error.message}")]
