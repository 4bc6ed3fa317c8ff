"""Whether an alarm's process condition holds now: one small check object per alarm.

A check returns the *raw* level — "" when the process is normal, else the level it is in
("hihi", "hi", "lo", "lolo" for limit alarms, "on" for the others) — before on/off delays,
which the engine applies. Checks read the `Tag` objects directly (they live as long as the
database): a limit alarm that stays normal costs two comparisons.
"""

from __future__ import annotations

import ast
from collections import deque
from collections.abc import Callable
from typing import Any

from softplc.adapters.alarms.settings import AlarmDefinition
from softplc.core.expression import Condition
from softplc.core.tagdb import TagDatabase
from softplc.core.tags import Quality

ON = "on"


class LimitCheck:
    """hihi/hi active at or above their limit, lo/lolo at or below; back to normal only past the deadband."""

    __slots__ = ("tag", "high", "low", "deadband", "high_edge", "low_edge", "severer")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        self.tag = db[definition.tag]
        self.deadband = definition.deadband
        order = {"hihi": 0, "hi": 1, "lolo": 0, "lo": 1}
        self.high = sorted((level for level in definition.levels if level.high), key=lambda level: order[level.name])
        self.low = sorted((level for level in definition.levels if not level.high), key=lambda level: order[level.name])
        # Between the edges (less the deadband) a normal alarm stays normal: the fast path.
        self.high_edge = min((level.limit for level in self.high), default=float("inf"))
        self.low_edge = max((level.limit for level in self.low), default=float("-inf"))
        # The levels at least as severe as each level, on its side (which keep it with the deadband).
        self.severer = {level.name: {other.name for other in side[: index + 1]}
                        for side in (self.high, self.low) for index, level in enumerate(side)}

    def __call__(self, level: str, now: float) -> str:
        value = self.tag.value
        if not level and self.low_edge < value < self.high_edge:
            return ""
        if value != value:  # NaN: no information, keep what we had
            return level
        deadband = self.deadband
        severer = self.severer
        for candidate in self.high:
            if value >= candidate.limit or (level in severer[candidate.name] and value > candidate.limit - deadband):
                return candidate.name
        for candidate in self.low:
            if value <= candidate.limit or (level in severer[candidate.name] and value < candidate.limit + deadband):
                return candidate.name
        return ""


class DiscreteCheck:
    """A tag in an alarm value, off its normal value, or of bad quality."""

    __slots__ = ("tag", "values", "mode")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        self.tag = db[definition.tag]
        self.values = definition.values
        self.mode = definition.discrete

    def __call__(self, level: str, now: float) -> str:
        tag = self.tag
        if self.mode == "value":
            holds = tag.value in self.values
        elif self.mode == "normal":
            holds = tag.value not in self.values
        else:
            holds = tag.quality is not Quality.GOOD
        return ON if holds else ""


def condition_check(definition: AlarmDefinition, db: TagDatabase) -> Check:
    """An expression over tags (the language of `run --until`), compiled."""
    condition = definition.condition
    assert condition is not None
    holds = compile_condition(condition, db, exact=False)
    value_of = db.value

    def check(level: str, now: float) -> str:
        try:
            return ON if holds() else ""
        except ZeroDivisionError:
            try:
                return ON if condition.evaluate(value_of) else ""  # makes it NaN, as run --until does
            except (TypeError, ValueError, ArithmeticError):
                return level
        except (TypeError, ValueError, ArithmeticError):  # e.g. a string compared with a number
            return level

    check.holds = holds  # type: ignore[attr-defined]  # the engine calls it inline, the check on errors
    return check


class _Compiler(ast.NodeTransformer):
    """Rewrites a checked condition: tag names read their Tag's value, and/or/not give booleans."""

    def __init__(self) -> None:
        self.tags: dict[str, str] = {}  # tag name → the lambda's parameter holding its Tag

    def visit_Name(self, node: ast.Name) -> ast.AST:
        if node.id in _CONSTANTS:
            return ast.copy_location(ast.Constant(_CONSTANTS[node.id]), node)
        return self._tag(node.id, node)

    def visit_Attribute(self, node: ast.Attribute) -> ast.AST:
        return self._tag(_dotted(node), node)  # a dotted tag name, e.g. _sys.plant.overruns

    def visit_BoolOp(self, node: ast.BoolOp) -> ast.AST:
        self.generic_visit(node)
        return ast.copy_location(ast.Call(ast.Name("bool", ast.Load()), [node], []), node)

    def _tag(self, name: str, node: ast.AST) -> ast.AST:
        parameter = self.tags.setdefault(name, f"_tag{len(self.tags)}")
        return ast.copy_location(ast.Attribute(ast.Name(parameter, ast.Load()), "value", ast.Load()), node)


_CONSTANTS = {"true": True, "false": False, "True": True, "False": False}


def _dotted(node: ast.AST) -> str:
    if isinstance(node, ast.Attribute):
        return _dotted(node.value) + "." + node.attr
    assert isinstance(node, ast.Name)
    return node.id


def compile_condition(condition: Condition, db: TagDatabase, *, exact: bool = True) -> Callable[[], Any]:
    """`condition` as a Python function of the tags' current values.

    Safe to compile: `Condition` accepted the text only if it holds nothing but names, constants,
    arithmetic, comparisons and and/or/not. With `exact`, a division by zero falls back to the
    condition's own evaluation (which makes it NaN), so both give the same answer; without, the
    function raises ZeroDivisionError and the caller falls back.
    """
    compiler = _Compiler()
    body = compiler.visit(ast.parse(condition.text.strip(), mode="eval")).body
    if isinstance(body, ast.Call) and isinstance(body.func, ast.Name) and body.func.id == "bool":
        body = body.args[0]  # at the top, truthiness is all that counts
    # lambda _tag0=<Tag>, _tag1=<Tag>: ... — each Tag a default argument, i.e. a fast local.
    parameters = [ast.arg(parameter) for parameter in compiler.tags.values()]
    defaults = [ast.Subscript(ast.Name("tags", ast.Load()), ast.Constant(name), ast.Load()) for name in compiler.tags]
    arguments = ast.arguments(posonlyargs=[], args=parameters, kwonlyargs=[], kw_defaults=[], defaults=defaults)
    code = compile(ast.fix_missing_locations(ast.Expression(ast.Lambda(arguments, body))), f"<alarm condition {condition.text!r}>", "eval")
    scope = {"__builtins__": {}, "bool": bool, "tags": {name: db[name] for name in condition.names}}
    compiled = eval(code, scope)  # noqa: S307 — makes the function of a checked expression, see the docstring
    if not exact:
        return compiled  # type: ignore[no-any-return]
    value_of = db.value

    def holds() -> Any:
        try:
            return compiled()
        except ZeroDivisionError:
            return condition.evaluate(value_of)

    return holds


class IncreaseCheck:
    """A counter that grew by at least `by` within the last `within` seconds (e.g. scan overruns).

    Only growth counts: a counter reset to 0 starts afresh. `next_change(now)` tells the engine
    when the window will have dropped the oldest growth, so it re-evaluates then.
    """

    __slots__ = ("tag", "by", "within", "last", "growth")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        self.tag = db[definition.tag]
        self.by = definition.increase_by
        self.within = definition.increase_within
        self.last = self.tag.value
        self.growth: deque[tuple[float, float]] = deque()

    def __call__(self, level: str, now: float) -> str:
        value = self.tag.value
        if value > self.last:
            self.growth.append((now, value - self.last))
        self.last = value
        growth = self.growth
        while growth and growth[0][0] <= now - self.within:
            growth.popleft()
        return ON if sum(amount for _, amount in growth) >= self.by else ""

    def next_change(self, now: float) -> float | None:
        return self.growth[0][0] + self.within if self.growth else None


Check = Callable[[str, float], str]
_CHECKS: dict[str, Callable[[AlarmDefinition, TagDatabase], Any]] = {
    "limit": LimitCheck, "discrete": DiscreteCheck, "condition": condition_check, "increase": IncreaseCheck,
}


def make_check(definition: AlarmDefinition, db: TagDatabase) -> Check:
    """The check of an alarm's kind, bound to the database's tags."""
    return _CHECKS[definition.kind](definition, db)
