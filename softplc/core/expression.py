"""Conditions over tag names, e.g. `t01_qSL >= 100 or t02_qSL >= 100` (for `run --until` and HMI views).

Only comparisons, arithmetic, `and`/`or`/`not`, numbers, strings, true/false and tag names are
allowed; nothing is executed as Python code.
"""

from __future__ import annotations

import ast
import operator
from collections.abc import Callable, Iterable
from typing import Any

from softplc.util.suggest import did_you_mean

_BINARY: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.Mod: operator.mod, ast.FloorDiv: operator.floordiv, ast.Pow: operator.pow,
}
_COMPARE: dict[type, Callable[[Any, Any], bool]] = {
    ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
    ast.Gt: operator.gt, ast.GtE: operator.ge,
}
_CONSTANTS = {"true": True, "false": False, "True": True, "False": False}


class ExpressionError(ValueError):
    pass


def _dotted(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return f"{base}.{node.attr}" if base else None
    return None


class Condition:
    """A parsed condition; `names` are the tags it reads."""

    def __init__(self, text: str, known: Iterable[str]) -> None:
        self.text = text
        try:
            self._tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError as error:
            raise ExpressionError(f"cannot parse {text!r}: {error.msg}") from None
        known_set = set(known)
        self.names: set[str] = set()
        self._check(self._tree, known_set)

    def _check(self, node: ast.AST, known: set[str]) -> None:
        name = _dotted(node)
        if name is not None:
            if name in _CONSTANTS:
                return
            if name not in known:
                raise ExpressionError(f"unknown tag '{name}' in condition{did_you_mean(name, known)}")
            self.names.add(name)
            return
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool)):
            return
        if isinstance(node, ast.BoolOp):
            for value in node.values:
                self._check(value, known)
            return
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.Not, ast.USub, ast.UAdd)):
            self._check(node.operand, known)
            return
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            self._check(node.left, known)
            self._check(node.right, known)
            return
        if isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
            self._check(node.left, known)
            for comparator in node.comparators:
                self._check(comparator, known)
            return
        raise ExpressionError(f"not allowed in a condition: {ast.unparse(node)!r}")

    def evaluate(self, values: Callable[[str], Any]) -> bool:
        """Evaluate with `values(tag_name)` giving each tag's current value."""
        return bool(self._eval(self._tree, values))

    def value(self, values: Callable[[str], Any]) -> Any:
        """The expression's own value (number, text or truth value), e.g. for an HMI text."""
        return self._eval(self._tree, values)

    def _eval(self, node: ast.AST, values: Callable[[str], Any]) -> Any:
        name = _dotted(node)
        if name is not None:
            return _CONSTANTS[name] if name in _CONSTANTS else values(name)
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.BoolOp):
            results = (self._eval(v, values) for v in node.values)
            return all(results) if isinstance(node.op, ast.And) else any(results)
        if isinstance(node, ast.UnaryOp):
            operand = self._eval(node.operand, values)
            if isinstance(node.op, ast.Not):
                return not operand
            return -operand if isinstance(node.op, ast.USub) else +operand
        if isinstance(node, ast.BinOp):
            try:
                return _BINARY[type(node.op)](self._eval(node.left, values), self._eval(node.right, values))
            except ZeroDivisionError:
                return float("nan")
        if isinstance(node, ast.Compare):
            left = self._eval(node.left, values)
            for op, comparator in zip(node.ops, node.comparators):
                right = self._eval(comparator, values)
                if not _COMPARE[type(op)](left, right):
                    return False
                left = right
            return True
        raise ExpressionError(f"cannot evaluate {ast.unparse(node)!r}")
