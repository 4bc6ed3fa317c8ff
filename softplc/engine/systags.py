"""Publishing the system tags under `_sys.` (declared in softplc/config/system_tags.py): runtime state,
per-task timing statistics, program states; and the two command tags `_sys.reset_stats`, `_sys.reset_faults`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from softplc.config.plant import SYSTEM_PREFIX
from softplc.config.system_tags import _SERIES, ERROR, FORCED, RESET_FAULTS, RESET_STATS, STATE, TIME
from softplc.core.tagdb import TagDatabase
from softplc.engine.scan import ScanEngine


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
