"""SciPy's `linear_sum_assignment` (the Hungarian method, in C) without importing all of `scipy.optimize`.

`from scipy.optimize import linear_sum_assignment` runs scipy.optimize's package `__init__`,
which imports linprog, the linear algebra, the sparse matrices… ~0.35 s of a simulated scenario
that ends in ~2.5 s, for a function in one compiled module that needs none of them
(`scipy/optimize/_lsap*.so`, which imports numpy only). That module is loaded on its own from
the installed SciPy (1.17 here); a SciPy that keeps it elsewhere gets the ordinary import.
The function is SciPy's either way (the same object once scipy.optimize is imported too).
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
from collections.abc import Callable
from pathlib import Path
from typing import Any


def linear_sum_assignment(cost: Any, maximize: bool = False) -> tuple[Any, Any]:
    """`scipy.optimize.linear_sum_assignment(cost, maximize)`: row indices and their columns."""
    return _scipy_function()(cost, maximize)


@functools.cache
def _scipy_function() -> Callable[..., tuple[Any, Any]]:
    scipy = importlib.util.find_spec("scipy")  # finds the package without importing it
    for location in (scipy.submodule_search_locations or []) if scipy is not None else []:
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = Path(location) / "optimize" / f"_lsap{suffix}"
            if path.is_file():
                spec = importlib.util.spec_from_file_location("scipy.optimize._lsap", path)
                if spec is not None and spec.loader is not None:
                    module = importlib.util.module_from_spec(spec)
                    spec.loader.exec_module(module)
                    function = getattr(module, "linear_sum_assignment", None)
                    if callable(function):
                        return function  # type: ignore[no-any-return]
    from scipy.optimize import linear_sum_assignment as function

    return function  # type: ignore[no-any-return]
