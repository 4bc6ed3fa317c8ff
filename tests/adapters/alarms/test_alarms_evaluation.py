"""The compiled form of an alarm condition answers exactly as the `--until` language's evaluator does."""

from __future__ import annotations

import itertools

import pytest

from softplc.adapters.alarms.evaluation import compile_condition
from softplc.core.datatypes import DataType
from softplc.core.expression import Condition
from softplc.core.tagdb import TagDatabase
from softplc.core.tags import TagDef

EXPRESSIONS = [
    "a > 3", "a > 3 and b", "not b or a <= 0", "(a or b) + 1 > 1", "a / c > 1", "c == 0 and a / c > 1", "1 < a < 5",
    "s == 'failed'", "_sys.x.count >= 2", "-a < 0 and not (b and false)", "a % 2 == 1 or true", "a ** 2 > 10",
]
VALUES = {"a": [0.0, 2.0, 4.0, -1.5], "b": [True, False], "c": [0.0, 2.0], "s": ["failed", "idle"], "_sys.x.count": [1, 3]}


@pytest.mark.parametrize("text", EXPRESSIONS)
def test_compiled_conditions_agree_with_the_evaluator(text: str) -> None:
    types = {"a": DataType.FLOAT64, "b": DataType.BOOL, "c": DataType.FLOAT64, "s": DataType.STRING, "_sys.x.count": DataType.UINT32}
    db = TagDatabase([TagDef(name, data_type, data_type.default) for name, data_type in types.items()], lambda: 0.0)
    condition = Condition(text, types)
    compiled = compile_condition(condition, db)
    for combination in itertools.product(*VALUES.values()):
        db.commit(dict(zip(VALUES, combination)))
        assert bool(compiled()) == condition.evaluate(db.value), (text, combination)
