"""SciPy's linear_sum_assignment loaded on its own: the same answers, without scipy.optimize's imports."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from softplc.util.assignment import linear_sum_assignment


@pytest.mark.parametrize("shape", [(1, 1), (3, 3), (3, 7), (7, 3), (12, 12)])
def test_the_same_assignment_as_scipy_optimize(shape: tuple[int, int]) -> None:
    from scipy.optimize import linear_sum_assignment as scipys

    rng = np.random.default_rng(sum(shape))
    for _ in range(20):
        cost = rng.integers(0, 5, size=shape).astype(float)  # many ties: the same choice among equals
        cost[rng.random(shape) < 0.2] = 1e6  # masked pairs, as the optimal dispatcher marks them
        for maximize in (False, True):
            ours, theirs = linear_sum_assignment(cost, maximize), scipys(cost, maximize=maximize)
            assert [a.tolist() for a in ours] == [a.tolist() for a in theirs]


def test_an_impossible_assignment_is_refused_as_scipy_refuses_it() -> None:
    with pytest.raises(ValueError, match="infeasible"):
        linear_sum_assignment(np.array([[np.inf, np.inf], [1.0, 2.0]]))


def test_scipy_optimize_itself_is_not_imported() -> None:
    code = ("import sys; import numpy as np; from softplc.util.assignment import linear_sum_assignment as f; "
            "rows, columns = f(np.array([[4.0, 1.0], [2.0, 0.5]])); "
            "print(columns.tolist(), 'scipy.optimize' in sys.modules, 'scipy.linalg' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60).stdout
    assert out.split() == ["[1,", "0]", "False", "False"]
