"""The independent tools the tests drive: a missing one skips its tests with how to install it,
except under CI (CI=true), where it fails them — a CI run must not pass by skipping."""

from __future__ import annotations

import os
from typing import NoReturn

import pytest

INSTALL = "scripts/install-test-tools.sh"


def under_ci() -> bool:
    """Whether this run is a CI run (CI=true, as CI services set it; also 1 or yes)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def missing(reason: str, *, module: bool = False) -> NoReturn:
    """Skip (the module, with `module`) because `reason` — or, under CI, fail with it."""
    if under_ci():
        pytest.fail(f"{reason} — under CI (CI=true) every test tool must be installed ({INSTALL}; ./test.sh runs it)", pytrace=False)
    pytest.skip(reason, allow_module_level=module)
