"""User mimics: SVG drawings whose elements are bound to tags in `hmi: views:` of tagdb.yaml.

    hmi:
      views:
        line:
          title: Material handling
          svg: hmi/views/material-handling.svg
          bindings:
            t01_in_level: {bar: {tag: t01_iBL, direction: up}, fill: {tag: t01_iBL, thresholds: [[0, "#3b7"], [90, "#d33"]]}}
            t01_in_text:  {text: {tag: t01_iBM, decimals: 0}}
            t01_alarm:    {visible: "t01_iBL >= 90"}
            r01:          {translate: {x: r01_xpos, y: r01_ypos, scale: [40, -40], offset: [20, 364]}}
            t01_pause:    {click: {tag: t01_iFr, write: 0}}

A binding's value source is an expression in the language of `--until` (a bare tag name is the
simplest one), or a mapping with `tag:` or `expr:`. Expressions are evaluated on the server
(`softplc.adapters.hmi.expressions`), so the page only ever receives values. Every unknown tag, unknown
element id, bad expression, colour or click value is a located problem of `softplc check`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.adapters.hmi.svg import SvgError, svg_ids
from softplc.core.datatypes import TypeMismatch
from softplc.core.expression import Condition, ExpressionError
from softplc.core.tags import TagDef
from softplc.util.suggest import did_you_mean

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

EXPRESSION_PREFIX = "="  # live items named "=<expression>" carry an expression's value; tag names never start so
_COLOR = re.compile(r"^(#[0-9a-fA-F]{3,8}|[a-zA-Z]{3,30}|(rgb|rgba|hsl|hsla)\([0-9., %/+-]{1,60}\))$")
_DIRECTIONS = ("up", "down", "left", "right")


@dataclass
class View:
    """One user mimic, compiled for the page: bindings refer to live item names."""

    name: str
    title: str
    svg: Path
    bindings: list[dict[str, Any]] = field(default_factory=list)
    expressions: dict[str, Condition] = field(default_factory=dict)  # live item name → condition

    @property
    def items(self) -> list[str]:
        """Every live item (tag or expression) the view shows."""
        names: dict[str, None] = {}
        for binding in self.bindings:
            for key in ("source", "x", "y", "tag"):
                name = binding.get(key)
                if isinstance(name, str) and (binding["kind"] != "click"):
                    names[name] = None
        return list(names)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "title": self.title, "svg": f"/api/views/{self.name}/svg", "bindings": self.bindings, "items": self.items}


def view_problems(config: PlantConfig) -> list[Problem]:
    """Located mistakes of `hmi: views:` (unknown tags and element ids, bad expressions...)."""
    return load_views(config)[1]


def load_views(config: PlantConfig) -> tuple[list[View], list[Problem]]:
    """The views of `hmi: views:`, and the problems found on the way (views with problems are left out)."""
    from softplc.config.system_tags import system_tag_definitions

    section = config.raw.get("hmi")
    views_section = section.get("views") if isinstance(section, dict) else None
    if not isinstance(views_section, dict):
        return [], []
    tags = {definition.name: definition for definition in [*config.tags, *system_tag_definitions(config.tasks)]}
    views: list[View] = []
    problems: list[Problem] = []
    for name, spec in views_section.items():
        if not isinstance(spec, dict) or not isinstance(spec.get("svg"), str):
            continue  # the schema said what is wrong
        compiler = _ViewCompiler(config, tags, ("hmi", "views", name))
        view = compiler.compile(name, spec)
        problems.extend(compiler.problems)
        if view is not None and not compiler.problems:
            views.append(view)
    return views, problems


class _ViewCompiler:
    def __init__(self, config: PlantConfig, tags: dict[str, TagDef], base: tuple[Any, ...]) -> None:
        self.config = config
        self.tags = tags
        self.base = base
        self.problems: list[Problem] = []
        self.expressions: dict[str, Condition] = {}

    def problem(self, path: tuple[Any, ...], message: str, *, at_key: bool = False) -> None:
        from softplc.config.yamlsource import Location, Problem

        source = self.config.source
        full = (*self.base, *path)
        self.problems.append(source.problem(full, message, at_key=at_key) if source else Problem(Location(str(self.config.path), 1, 1), message))

    def compile(self, name: str, spec: dict[str, Any]) -> View | None:
        svg = self.config.base_dir / spec["svg"]
        if not svg.is_file():
            self.problem(("svg",), f"view '{name}': SVG file not found: {svg}")
            return None
        try:
            ids = svg_ids(svg)
        except SvgError as error:
            self.problem(("svg",), f"view '{name}': {error}")
            return None
        view = View(name, str(spec.get("title") or name), svg)
        bindings = spec.get("bindings") if isinstance(spec.get("bindings"), dict) else {}
        for element, binding in bindings.items():
            element = str(element)
            if element not in ids:
                self.problem(("bindings", element), f"view '{name}': the SVG has no element with id '{element}'{did_you_mean(element, ids)}", at_key=True)
                continue
            if not isinstance(binding, dict):
                continue
            for kind, options in binding.items():
                compiled = self._binding(element, ids[element], kind, options, ("bindings", element, kind))
                if compiled is not None:
                    view.bindings.append(compiled)
        view.expressions = self.expressions
        return view

    # -- one binding --------------------------------------------------------------------------

    def _binding(self, element: str, element_type: str, kind: str, options: Any, path: tuple[Any, ...]) -> dict[str, Any] | None:
        compiled: dict[str, Any] = {"id": element, "kind": kind}
        if kind == "click":
            return self._click(compiled, options, path)
        if kind == "translate":
            if not isinstance(options, dict):
                return None
            for axis in ("x", "y"):
                if axis in options:
                    compiled[axis] = self._source(options[axis], (*path, axis))
            scale = options.get("scale", 1.0)
            compiled["scale"] = [float(scale), float(scale)] if isinstance(scale, (int, float)) else [float(v) for v in scale]
            compiled["offset"] = [float(v) for v in options.get("offset", (0.0, 0.0))]
            return compiled if any(compiled.get(axis) for axis in ("x", "y")) else None
        source = self._source(options, path)
        if source is None:
            return None
        compiled["source"] = source
        settings = options if isinstance(options, dict) else {}
        definition = self.tags.get(source)
        if kind == "text":
            compiled["decimals"] = settings.get("decimals")
            compiled["unit"] = settings.get("unit", definition.unit if definition else "")
            if "map" in settings:
                compiled["map"] = {str(key): str(value) for key, value in settings["map"].items()}
        elif kind in ("fill", "stroke"):
            self._colours(compiled, settings, path)
        elif kind == "bar":
            if element_type != "rect":
                self.problem(path, f"a bar must be a <rect>, but '{element}' is a <{element_type}>", at_key=True)
                return None
            low = settings.get("min", definition.min if definition and definition.min is not None else 0.0)
            high = settings.get("max", definition.max if definition and definition.max is not None else 100.0)
            if high <= low:
                self.problem(path, f"a bar's max ({high:g}) must be above its min ({low:g})", at_key=True)
                return None
            compiled.update(min=float(low), max=float(high), direction=settings.get("direction", "up"))
        elif kind == "rotate":
            compiled["scale"] = float(settings.get("scale", 1.0))
            compiled["offset"] = float(settings.get("offset", 0.0))
            compiled["center"] = [float(v) for v in settings["center"]] if "center" in settings else None
        return compiled

    def _source(self, options: Any, path: tuple[Any, ...]) -> str | None:
        """The live item a source names: the tag itself, or '=<expression>'."""
        if isinstance(options, str):
            return self._expression(options, path)
        if not isinstance(options, dict):
            return None
        if "tag" in options and "expr" in options:
            self.problem((*path, "expr"), "give either 'tag' or 'expr', not both", at_key=True)
            return None
        if "tag" in options:
            name = str(options["tag"])
            if name not in self.tags:
                self.problem((*path, "tag"), f"unknown tag '{name}'{did_you_mean(name, self.tags)}")
                return None
            return name
        if "expr" in options:
            return self._expression(str(options["expr"]), (*path, "expr"))
        self.problem(path, "say which value drives it: 'tag: NAME' or 'expr: EXPRESSION'", at_key=True)
        return None

    def _expression(self, text: str, path: tuple[Any, ...]) -> str | None:
        text = text.strip()
        if text in self.tags:
            return text
        try:
            condition = Condition(text, self.tags)
        except ExpressionError as error:
            self.problem(path, str(error).replace("in condition", "in expression"))
            return None
        key = EXPRESSION_PREFIX + text
        self.expressions[key] = condition
        return key

    def _colours(self, compiled: dict[str, Any], settings: dict[str, Any], path: tuple[Any, ...]) -> None:
        for key in ("on_color", "off_color"):
            if key in settings:
                compiled[key] = self._colour(settings[key], (*path, key))
        if "thresholds" in settings:
            steps = []
            for index, step in enumerate(settings["thresholds"]):
                if not (isinstance(step[0], (int, float)) and not isinstance(step[0], bool)):
                    self.problem((*path, "thresholds", index), f"a threshold is [value, colour], and {step[0]!r} is not a number")
                    continue
                steps.append([float(step[0]), self._colour(step[1], (*path, "thresholds", index))])
            compiled["thresholds"] = sorted(steps, key=lambda step: step[0])
        if not any(key in compiled for key in ("on_color", "off_color", "thresholds")):
            self.problem(path, "give colours: 'on_color:'/'off_color:' or 'thresholds: [[value, colour], ...]'", at_key=True)

    def _colour(self, value: Any, path: tuple[Any, ...]) -> str:
        if not isinstance(value, str) or not _COLOR.match(value):
            self.problem(path, f"not a colour: {value!r} (write #rgb, #rrggbb, a name such as red, or rgb(...))")
            return "black"
        return value

    def _click(self, compiled: dict[str, Any], options: Any, path: tuple[Any, ...]) -> dict[str, Any] | None:
        if not isinstance(options, dict):
            return None
        if "dialog" in options:
            name = str(options["dialog"])
            if name not in self.tags:
                self.problem((*path, "dialog"), f"unknown tag '{name}'{did_you_mean(name, self.tags)}")
                return None
            compiled["dialog"] = name
            return compiled
        if "tag" not in options or "write" not in options:
            self.problem(path, "a click writes 'write: VALUE' to 'tag: NAME', or opens 'dialog: NAME'", at_key=True)
            return None
        name = str(options["tag"])
        definition = self.tags.get(name)
        if definition is None:
            self.problem((*path, "tag"), f"unknown tag '{name}'{did_you_mean(name, self.tags)}")
            return None
        problem = _value_problem(definition, options["write"])
        if problem:
            self.problem((*path, "write"), f"{problem} (tag {name})")
            return None
        compiled.update(tag=name, write=definition.type.coerce(options["write"]))
        return compiled


def _value_problem(definition: TagDef, value: Any) -> str:
    """Why `value` cannot be written to the tag (type or range), or ''."""
    try:
        coerced = definition.type.coerce(value)
    except TypeMismatch as error:
        return str(error)
    if definition.min is not None and coerced < definition.min:
        return f"{coerced} is below the minimum {definition.min:g}"
    if definition.max is not None and coerced > definition.max:
        return f"{coerced} is above the maximum {definition.max:g}"
    return ""
