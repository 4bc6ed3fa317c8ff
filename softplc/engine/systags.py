"""System tags under `_sys.`: runtime state, per-task timing statistics, program states.

They are ordinary tags (served over every protocol like the plant's own), written by the
runtime. Two are commands for clients: write true to `_sys.reset_stats` to restart the timing
statistics, or to `_sys.reset_faults` to clear program faults and the runtime ERROR state.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from softplc.config.plant import SYSTEM_PREFIX, PlantConfig, TaskConfig
from softplc.core.datatypes import DataType
from softplc.engine.scan import ScanEngine
from softplc.core.tagdb import TagDatabase
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


class SystemTags:
    """Publishes the engine's state into the `_sys.` tags and executes the reset commands."""

    def __init__(self, db: TagDatabase, engine: ScanEngine, state: Callable[[], tuple[str, str]], reset_faults: Callable[[], None]) -> None:
        self.db = db
        self.engine = engine
        self._state = state
        self._reset_faults = reset_faults

    def publish(self, now: float) -> None:
        """Write the current figures (only changed values reach subscribers)."""
        db = self.db
        values: dict[str, Any] = {}
        if db.value(RESET_STATS):
            for task in self.engine.tasks:
                task.stats.reset()
            values[RESET_STATS] = False
        if db.value(RESET_FAULTS):
            self._reset_faults()
            values[RESET_FAULTS] = False
        values.update(self._state_values())
        values[TIME] = float(now)
        values[FORCED] = len(db.forces)
        for task in self.engine.tasks:
            prefix = f"{SYSTEM_PREFIX}{task.name}."
            stats = task.stats
            values[prefix + "interval_ms"] = task.interval * 1e3
            values[prefix + "cycles"] = stats.cycles % 2**32
            values[prefix + "overruns"] = stats.overruns % 2**32
            values[prefix + "watchdog_trips"] = stats.watchdog_trips % 2**32
            for series in _SERIES:
                for stat, figure in getattr(stats, series).summary().items():
                    values[f"{prefix}{series}_ms_{stat}"] = float(figure)
        db.commit(values)

    def publish_state(self) -> None:
        """Write the runtime's and the programs' states now, between two publications (after a stall)."""
        self.db.commit(self._state_values())

    def _state_values(self) -> dict[str, Any]:
        state, error = self._state()
        values: dict[str, Any] = {STATE: state, ERROR: error}
        for task in self.engine.tasks:
            prefix = f"{SYSTEM_PREFIX}{task.name}."
            for instance in task.programs:
                program_prefix = f"{prefix}{instance.name}."
                values[program_prefix + "state"] = instance.state.value
                values[program_prefix + "error"] = instance.error
                values[program_prefix + "faults"] = instance.faults % 2**32
        return values
