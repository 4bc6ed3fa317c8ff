"""The `audit:` section: on by default, its mistakes located by `softplc check`, off only when asked."""

from __future__ import annotations

import argparse
import re
import textwrap
from pathlib import Path

import pytest

from softplc.app.adapters import build_adapters
from softplc.app.cli import build_parser, main
from softplc.config import load_config, sections
from softplc.storage.audit.settings import DEFAULT_PARTITION, DEFAULT_RETENTION, AuditSettings

PLANT = """\
version: 1
plant: {name: settings-test}
tags:
  level: {type: float64}
servers:
  opcua: {enabled: false}
  modbus: {enabled: false}
  hmi: {enabled: false}
"""


def write(tmp_path: Path, audit: str = "") -> Path:
    path = tmp_path / "tagdb.yaml"
    path.write_text(PLANT + (textwrap.dedent(audit) if audit else ""))
    return path


def test_without_a_section_the_trail_is_kept_with_the_defaults_and_starts_first(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, "alarms:\n  definitions:\n    - {name: hi, limit: {tag: level, hi: 9}}\n"))
    settings = AuditSettings.from_config(config)
    assert (settings.enabled, settings.retention, settings.partition) == (True, DEFAULT_RETENTION, DEFAULT_PARTITION)
    assert settings.storage(tmp_path).path == tmp_path / "audit.sqlite" and settings.storage(tmp_path).flush_period == 1.0
    assert settings.storage(tmp_path, simulated=True).path == tmp_path / "audit-sim.sqlite"
    assert [adapter.name for adapter in build_adapters(config, None)] == ["audit", "alarms"]  # listening before any other


def test_it_is_off_only_when_asked(tmp_path: Path) -> None:
    config = load_config(write(tmp_path))
    parser = build_parser()
    assert [a.name for a in build_adapters(config, parser.parse_args(["run", "--no-audit"]))] == []
    assert [a.name for a in build_adapters(config, parser.parse_args(["run", "--no-servers"]))] == ["audit"]
    assert [a.name for a in build_adapters(config, argparse.Namespace(sim=True))] == ["audit"]
    off = load_config(write(tmp_path, "audit: {enabled: false}\n"))
    assert build_adapters(off, None) == []


def test_a_configured_section(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, """
        audit:
          backend: postgresql
          dsn: "host=db.example dbname=plant"
          retention: 2w
          partition: 6h
          flush_period: 200ms
        """))
    settings = AuditSettings.from_config(config)
    assert (settings.retention, settings.partition) == (14 * 86400.0, 6 * 3600.0)
    storage = settings.storage(tmp_path)
    assert (storage.backend, storage.dsn, storage.flush_period) == ("postgresql", "host=db.example dbname=plant", 0.2)
    assert settings.storage(tmp_path, simulated=True).backend == "sqlite"  # --sim never writes to the plant's server
    assert AuditSettings.from_config(load_config(write(tmp_path, "audit: {retention: 0}\n"))).retention is None


MISTAKES = """\
audit:
  retention: 10min
  partition: 90min
  flush_period: 5 parsecs
  backend: postgresql
  path: audit.sqlite
"""


def test_every_mistake_is_located_at_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, MISTAKES)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    first = PLANT.count("\n") + 1  # the line of 'audit:'
    problems = {int(match.group(1)) - first: match.group(2) for match in re.finditer(rf"^{re.escape(str(path))}:(\d+):\d+: (.*)$", err, re.M)}
    assert problems == {
        4: "backend postgresql needs a dsn, e.g. dsn: 'host=127.0.0.1 port=5432 dbname=plant'",
        5: "path is for backend: sqlite (this section uses postgresql)",
        3: "bad flush_period '5 parsecs': not a duration: '5 parsecs' (write e.g. 10ms, 1s, 2min)",
        1: "retention 10min is shorter than an hour: an audit trail that short answers no question; write e.g. 30d, or 0 to keep everything",
        2: "partition must be a whole number of hours (e.g. 24h, 1d, 1w), not 90min",
    }, err
    path.write_text(PLANT + "audit: {enabled: yes please, keep: 3d}\n")
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "keep" in err and "enabled" in err


def test_the_section_is_in_the_registry_and_the_schema() -> None:
    assert ("audit",) in [section.path for section in sections.registered()]
    schema = sections.config_schema()["properties"]["audit"]
    assert {"enabled", "backend", "path", "dsn", "flush_period", "retention", "partition"} == set(schema["properties"])
