"""The system tags under `_sys.` a plant has: their names and declarations, from the configuration alone.

They are ordinary tags (served over every protocol like the plant's own), written by the
runtime (softplc/engine/systags.py publishes them). Two are commands for clients: write true to
`_sys.reset_stats` to restart the timing statistics, or to `_sys.reset_faults` to clear program
faults and the runtime ERROR state.
"""

from __future__ import annotations

from softplc.config.plant import SYSTEM_PREFIX, PlantConfig, TaskConfig
from softplc.core.datatypes import DataType
from softplc.core.tags import Access, TagDef

_SERIES = ("scan", "cycle", "latency")
_STATS = ("min", "max", "mean", "p99")
_SERIES_TEXT = {"scan": "scan time", "cycle": "cycle time", "latency": "start latency"}
RESET_STATS = SYSTEM_PREFIX + "reset_stats"
RESET_FAULTS = SYSTEM_PREFIX + "reset_faults"
STATE = SYSTEM_PREFIX + "state"
ERROR = SYSTEM_PREFIX + "error"
TIME = SYSTEM_PREFIX + "time"
FORCED = SYSTEM_PREFIX + "forced"


def _tag(name: str, data_type: DataType, description: str, *, unit: str = "", access: Access = Access.RO, group: str = "_sys") -> TagDef:
    # Only the command tags (rw) accept client writes; every other system tag is the runtime's own.
    return TagDef(name=name, type=data_type, initial=data_type.default, unit=unit, description=description, access=access,
                  group=group, runtime_only=access is Access.RO)


def system_tag_definitions(tasks: list[TaskConfig]) -> list[TagDef]:
    """Declarations of every `_sys.` tag for the given tasks."""
    definitions = [
        _tag(STATE, DataType.STRING, "runtime state: RUNNING, ERROR, STOPPING"),
        _tag(ERROR, DataType.STRING, "last runtime error (empty when none)"),
        _tag(TIME, DataType.FLOAT64, "runtime clock (simulated under --sim)", unit="s"),
        _tag(FORCED, DataType.UINT32, "number of forced tags"),
        _tag(RESET_STATS, DataType.BOOL, "write true to reset all timing statistics", access=Access.RW),
        _tag(RESET_FAULTS, DataType.BOOL, "write true to clear program faults and the ERROR state", access=Access.RW),
    ]
    for task in tasks:
        prefix = f"{SYSTEM_PREFIX}{task.name}."
        group = f"_sys/{task.name}"
        definitions.append(_tag(prefix + "interval_ms", DataType.FLOAT64, f"interval of task {task.name}", unit="ms", group=group))
        for counter, text in (("cycles", "cycles run"), ("overruns", "releases skipped because a cycle overran"), ("watchdog_trips", "scans longer than the watchdog")):
            definitions.append(_tag(prefix + counter, DataType.UINT32, f"{task.name}: {text}", group=group))
        for series in _SERIES:
            for stat in _STATS:
                definitions.append(
                    _tag(f"{prefix}{series}_ms_{stat}", DataType.FLOAT64, f"{task.name}: {_SERIES_TEXT[series]}, {stat}", unit="ms", group=group)
                )
        for program in task.programs:
            program_prefix = f"{prefix}{program.name}."
            definitions.append(_tag(program_prefix + "state", DataType.STRING, f"program {program.name}: RUNNING, FAULTED or STOPPED", group=group))
            definitions.append(_tag(program_prefix + "error", DataType.STRING, f"program {program.name}: last error", group=group))
            definitions.append(_tag(program_prefix + "faults", DataType.UINT32, f"program {program.name}: faults so far", group=group))
    return definitions


def runtime_tag_definitions(config: PlantConfig) -> list[TagDef]:
    """The tags a runtime adds to the plant's own: the system tags and those the section owners contribute."""
    return [*system_tag_definitions(config.tasks), *config.contributed_tags]
