"""The thesis's case studies as reproducible scenarios (docs/case-studies.md).

    scenario = load_scenario(find_scenario("case1-sim1"))   # or a path to your own YAML
    result = run_scenario(scenario, Path("runs/case1-sim1"))
    result.summary["goals_per_task"]                           # {"t01": 6, "t02": 3}
"""

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from softplc.scenarios.runner import RunResult, run_scenario, run_scenario_async
    from softplc.scenarios.spec import Scenario, builtin_scenarios, find_scenario, load_scenario

# Public names and their modules, imported on first use (PEP 562): `softplc --help` imports
# softplc.scenarios.commands and must not load the runner (the fleet, numpy, scipy) with it.
_MODULES = {
    "softplc.scenarios.runner": ("RunResult", "run_scenario", "run_scenario_async"),
    "softplc.scenarios.spec": ("Scenario", "builtin_scenarios", "find_scenario", "load_scenario"),
}
_EXPORTS = {name: module for module, names in _MODULES.items() for name in names}

__all__ = ["RunResult", "Scenario", "builtin_scenarios", "find_scenario", "load_scenario", "run_scenario", "run_scenario_async"]


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value  # the next lookup does not come here
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
