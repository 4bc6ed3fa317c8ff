"""The storage keys of a YAML section: which backend, where, and how often the writer commits."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from softplc.config.yamlsource import Problem, SourceMap
from softplc.util.durations import parse_duration
from softplc.util.timestamps import parse_span

BACKENDS = ("sqlite", "postgresql")
DEFAULT_FLUSH_PERIOD = 1.0
MAX_FLUSH_PERIOD = 60.0

STORAGE_PROPERTIES: dict[str, Any] = {
    "backend": {"enum": list(BACKENDS), "description": "sqlite (default: a file in the state directory) or postgresql (a shared server, see dsn)."},
    "path": {"type": "string", "description": "SQLite file, relative to the state directory."},
    "dsn": {
        "type": "string",
        "description": "PostgreSQL connection string, e.g. 'host=db.example port=5432 dbname=plant user=softplc' "
        "(passwords from PGPASSWORD or ~/.pgpass, not from this file).",
    },
    "flush_period": {
        "description": "How often the writer commits what was recorded (default 1s): a crash loses at most this much.",
        "type": ["string", "number"],
    },
}

@dataclass(frozen=True)
class StorageSettings:
    """Resolved storage settings: a SQLite file or a PostgreSQL DSN, and the flush period (s)."""

    backend: str = "sqlite"
    path: Path | None = None  # SQLite only
    dsn: str = ""  # PostgreSQL only
    flush_period: float = DEFAULT_FLUSH_PERIOD

    @classmethod
    def from_section(cls, section: Mapping[str, Any] | None, state_dir: Path, default_file: str) -> StorageSettings:
        """Settings from a checked section (see `storage_problems`); the SQLite file defaults to STATE_DIR/default_file."""
        section = section or {}
        backend = str(section.get("backend", "sqlite"))
        path = state_dir / str(section.get("path", default_file))
        flush = parse_duration(section["flush_period"]) if "flush_period" in section else DEFAULT_FLUSH_PERIOD
        return cls(backend=backend, path=path if backend == "sqlite" else None, dsn=str(section.get("dsn", "")), flush_period=flush)

    @classmethod
    def for_run(cls, section: Mapping[str, Any] | None, state_dir: Path, default_file: str, sim_file: str, *,
                simulated: bool) -> StorageSettings:
        """The configured store; for a --sim run always STATE_DIR/sim_file (simulated times never mix with the plant's)."""
        settings = cls.from_section(section, state_dir, default_file)
        return cls.sqlite(state_dir / sim_file, settings.flush_period) if simulated else settings

    @classmethod
    def sqlite(cls, path: Path, flush_period: float = DEFAULT_FLUSH_PERIOD) -> StorageSettings:
        return cls(backend="sqlite", path=path, flush_period=flush_period)

    @classmethod
    def postgresql(cls, dsn: str, flush_period: float = DEFAULT_FLUSH_PERIOD) -> StorageSettings:
        return cls(backend="postgresql", dsn=dsn, flush_period=flush_period)

    def describe(self) -> str:
        """Where the records go, for the user (no password shown)."""
        if self.backend == "sqlite":
            return f"SQLite {self.path}"
        shown = re.sub(r"password\s*=\s*\S+", "password=***", self.dsn)
        shown = re.sub(r"://([^:/@]+):[^@]*@", r"://\1:***@", shown)
        return f"PostgreSQL {shown}"


def storage_problems(section: Any, where: Sequence[str | int], source: SourceMap | None) -> list[Problem]:
    """Mistakes in the storage keys of `section` (found at path `where`) that a schema cannot see."""
    if not isinstance(section, Mapping) or source is None:
        return []
    problems: list[Problem] = []
    backend = section.get("backend", "sqlite")
    if backend == "postgresql" and not str(section.get("dsn", "")).strip():
        problems.append(source.problem((*where, "backend"), "backend postgresql needs a dsn, e.g. dsn: 'host=127.0.0.1 port=5432 dbname=plant'"))
    if backend == "sqlite" and "dsn" in section:
        problems.append(source.problem((*where, "dsn"), "dsn is for backend: postgresql (this section uses sqlite)", at_key=True))
    if backend == "postgresql" and "path" in section:
        problems.append(source.problem((*where, "path"), "path is for backend: sqlite (this section uses postgresql)", at_key=True))
    if "path" in section and isinstance(section["path"], str) and not section["path"].strip():
        problems.append(source.problem((*where, "path"), "path must name a file"))
    if "flush_period" in section:
        value = section["flush_period"]
        try:
            seconds = parse_duration(value)
        except (TypeError, ValueError) as error:
            problems.append(source.problem((*where, "flush_period"), f"bad flush_period {value!r}: {error}"))
        else:
            if not 0 < seconds <= MAX_FLUSH_PERIOD:
                problems.append(source.problem((*where, "flush_period"), f"flush_period must be more than 0 and at most {MAX_FLUSH_PERIOD:g}s, not {value}"))
    return problems


def partitioned_spans(section: Mapping[str, Any], default_retention: float, default_partition: float) -> tuple[float | None, float]:
    """A time-partitioned store's retention (None: keep everything, written 0) and partition size, in seconds."""
    retention = section.get("retention", default_retention)
    return (None if retention in (0, "0", None) else parse_span(retention)), parse_span(section.get("partition", default_partition))


def span_problems(section: Mapping[str, Any], where: Sequence[str | int], source: SourceMap) -> list[Problem]:
    """Mistakes of a time-partitioned store's `retention` (0 keeps everything) and `partition` (whole hours)."""
    problems: list[Problem] = []
    for key in ("retention", "partition"):
        if key not in section or (key == "retention" and section[key] in (0, "0")):
            continue
        try:
            seconds = parse_span(section[key])
        except (TypeError, ValueError) as error:
            problems.append(source.problem((*where, key), f"bad {key} {section[key]!r}: {error}"))
            continue
        if key == "partition" and (seconds < 3600 or seconds % 3600):
            problems.append(source.problem((*where, key), f"partition must be a whole number of hours (e.g. 24h, 1d, 1w), not {section[key]}"))
    return problems
