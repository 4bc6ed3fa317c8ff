"""Load and validate a plant configuration (`tagdb.yaml`) into checked, expanded settings.

    config = load_config("tagdb.yaml")      # PlantConfig, or ConfigError listing every FILE:LINE:COL problem

One module per concept: `plant` (what a checked configuration is), `loader` (the order of the
checks), `schema_check` (JSON Schema violations as messages), `tags` and `templates` (tag
declarations), `tasks` and `programs` (tasks, program classes, bindings, parameters),
`outputs` (tags written by two programs), `findings` (problems said once). The sections other
modules own (servers, fleet, runtime...) are checked through `softplc.config.sections`.
"""

from softplc.config.loader import check_config, load_config, parse_config
from softplc.config.plant import SYSTEM_PREFIX, PlantConfig, ProgramConfig, TaskConfig
from softplc.config.programs import import_program
from softplc.config.schema_check import schema_problems
from softplc.util.durations import check_duration
from softplc.util.suggest import did_you_mean

__all__ = [
    "SYSTEM_PREFIX", "PlantConfig", "ProgramConfig", "TaskConfig", "check_config", "check_duration", "did_you_mean",
    "import_program", "load_config", "parse_config", "schema_problems",
]
