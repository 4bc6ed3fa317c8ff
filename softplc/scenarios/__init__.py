"""The thesis's case studies as reproducible scenarios (docs/case-studies.md).

    scenario = load_scenario(find_scenario("case1-sim1"))   # or a path to your own YAML
    result = run_scenario(scenario, Path("runs/case1-sim1"))
    result.summary["goals_per_task"]                           # {"t01": 6, "t02": 3}
"""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.scenarios.runner import RunResult, run_scenario, run_scenario_async
    from softplc.scenarios.spec import Scenario, builtin_scenarios, find_scenario, load_scenario

# Public names and their modules, imported on first use (PEP 562): `softplc --help` imports
# softplc.scenarios.cli and must not load the runner (the fleet, numpy, scipy) with it.
_MODULES = {
    "softplc.scenarios.runner": ("RunResult", "run_scenario", "run_scenario_async"),
    "softplc.scenarios.spec": ("Scenario", "builtin_scenarios", "find_scenario", "load_scenario"),
}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = ["RunResult", "Scenario", "builtin_scenarios", "find_scenario", "load_scenario", "run_scenario", "run_scenario_async"]
