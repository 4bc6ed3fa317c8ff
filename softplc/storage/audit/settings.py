"""The `audit:` section: whether the audit trail is kept, where, for how long, how often it is committed.

    audit:                  # optional: without it the trail is kept with these defaults
      enabled: true         # default true
      backend: sqlite       # or postgresql with dsn: (softplc.storage)
      path: audit.sqlite    # in the state directory
      retention: 90d        # whole partitions older than this are dropped (0: keep everything)
      partition: 1d         # time span of one partition (table), whole hours
      flush_period: 1s      # a kill -9 loses at most this much

Plain data and functions: the schema fragment `AUDIT_SCHEMA`, `AuditSettings.from_config`, `problems`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.storage.settings import (
    STORAGE_PROPERTIES,
    StorageSettings,
    parse_span,
    partitioned_spans,
    span_problems,
    storage_problems,
)

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

DEFAULT_FILE = "audit.sqlite"
SIM_FILE = "audit-sim.sqlite"  # --sim runs: simulated timestamps, never mixed with the plant's own trail
DEFAULT_RETENTION = 90 * 86400.0
DEFAULT_PARTITION = 86400.0
_SPAN = {"description": "A duration: 1h, 24h, 30d, 1w, or a number of seconds.", "type": ["string", "number"]}

AUDIT_SCHEMA: dict[str, Any] = {
    "description": "The audit trail (docs/operations.md): every client write and every command, accepted or refused.",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: keep no audit trail (default true, also without this section)."},
        **STORAGE_PROPERTIES,
        "retention": {**_SPAN, "description": "Keep this much of the trail; older partitions are dropped whole (default 90d; 0 keeps everything)."},
        "partition": {**_SPAN, "description": "Time span of one partition (table), a whole number of hours (default 1d)."},
    },
    "additionalProperties": False,
}


@dataclass(frozen=True)
class AuditSettings:
    """Resolved `audit:` settings."""

    enabled: bool = True
    section: Mapping[str, Any] = field(default_factory=dict)
    retention: float | None = DEFAULT_RETENTION  # None: keep everything
    partition: float = DEFAULT_PARTITION

    @classmethod
    def from_config(cls, config: PlantConfig) -> AuditSettings:
        """Settings of a checked configuration (see `problems`); defaults without an `audit:` section."""
        section = config.section("audit") or {}
        retention, partition = partitioned_spans(section, DEFAULT_RETENTION, DEFAULT_PARTITION)
        return cls(enabled=bool(section.get("enabled", True)), section=section, retention=retention, partition=partition)

    def storage(self, state_dir: Path, *, simulated: bool = False) -> StorageSettings:
        """Where to keep the trail: the configured store, or for a --sim run always STATE_DIR/audit-sim.sqlite."""
        return StorageSettings.for_run(self.section, state_dir, DEFAULT_FILE, SIM_FILE, simulated=simulated)


def problems(config: PlantConfig) -> list[Problem]:
    """Located mistakes of the `audit:` section that its schema cannot see."""
    section = config.section("audit")
    source = config.source
    if section is None or source is None:
        return []
    found = storage_problems(section, ("audit",), source) + span_problems(section, ("audit",), source)
    retention = section.get("retention", 0)
    try:
        too_short = retention not in (0, "0") and parse_span(retention) < 3600
    except (TypeError, ValueError):  # reported by span_problems
        too_short = False
    if too_short:
        found.append(source.problem(("audit", "retention"), f"retention {retention} is shorter than an hour: an audit trail that short "
                                                            "answers no question; write e.g. 30d, or 0 to keep everything"))
    return found
