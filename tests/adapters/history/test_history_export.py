"""`softplc history tags` and `softplc history export`: CSV and JSON, processed values, clear refusals."""

from __future__ import annotations

import csv
import io
import json
import textwrap
from pathlib import Path

import pytest
from conftest import REPO

from softplc.app.cli import main

SUPPORT = REPO / "tests" / "history_support.py"

PLANT = f"""
version: 1
plant: {{name: waves}}
tags:
  wave:  {{type: float64, min: -1, max: 1}}
  steps: {{type: int32}}
  state: {{type: string}}
tasks:
  main:
    interval: 100ms
    programs:
      - {{name: wave, program: "{SUPPORT}:Wave", bind: {{wave: wave, steps: steps, state: state}}}}
servers: {{opcua: {{enabled: false}}, modbus: {{enabled: false}}}}  # no server on a fixed port
history:
  record:
    - {{tags: [wave, steps, state]}}
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A plant that ran 20 simulated seconds with `softplc run --sim` (its history in history-sim.sqlite)."""
    directory = tmp_path_factory.mktemp("export")
    config = directory / "tagdb.yaml"
    config.write_text(textwrap.dedent(PLANT))
    assert main(["run", str(config), "--sim", "--duration", "20", "--no-status"]) == 0
    return config


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(["history", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_export_writes_csv_of_the_tags_matched(recorded: Path, capsys) -> None:
    code, out, err = run(capsys, "export", "st*", "--sim", "--config", str(recorded), "--from", "2026-01-01T00:00:05Z", "--to=2026-01-01T00:00:08")
    assert code == 0, err
    rows = list(csv.reader(io.StringIO(out)))
    assert rows[0] == ["tag", "time", "value", "quality"]
    steps = [row for row in rows[1:] if row[0] == "steps"]
    assert [row[1:] for row in steps] == [["2026-01-01T00:00:05.000Z", "5", "good"], ["2026-01-01T00:00:06.000Z", "6", "good"],
                                         ["2026-01-01T00:00:07.000Z", "7", "good"]]
    assert not [row for row in rows[1:] if row[0] == "state"]  # 'st*' matched it, but it did not change in [5 s, 8 s)


def test_export_processed_values_as_json(recorded: Path, capsys) -> None:
    code, out, err = run(capsys, "export", "steps", "--sim", "--config", str(recorded), "--from=-10s", "--interval", "5s",
                         "--aggregate", "maximum", "--format", "json")
    assert code == 0, err
    document = json.loads(out)
    assert document["plant"] == "waves" and document["aggregate"] == "maximum"
    # The last sample is at 19 s: --from=-10s is 9 s; maxima of [9, 14), [14, 19) and [19, the end].
    assert [point["value"] for point in document["tags"]["steps"]] == [13, 18, 19]
    code, out, err = run(capsys, "tags", "--sim", "--config", str(recorded))
    assert code == 0 and "steps" in out and "stepped" in out and "2026-01-01T00:00:19.000Z" in out


def test_export_says_clearly_when_there_is_nothing(recorded: Path, tmp_path: Path, capsys) -> None:
    code, _, err = run(capsys, "export", "nothing*", "--sim", "--config", str(recorded))
    assert code == 1 and "no history of 'nothing*' (plant 'waves'); tags with history: state, steps, wave" in err
    code, _, err = run(capsys, "export", "wave", "--config", str(recorded))  # the real plant never ran
    assert code == 1 and "no history yet:" in err and "history.sqlite does not exist (it is created by `softplc run`)" in err
    bare = tmp_path / "bare.yaml"
    bare.write_text("version: 1\ntags:\n  x: {type: bool}\n")
    code, _, err = run(capsys, "export", "x", "--config", str(bare))
    assert code == 1 and "has no history: section, so nothing is recorded" in err
    code, _, err = run(capsys, "export", "wave", "--sim", "--config", str(recorded), "--from", "yesterday")
    assert code == 1 and "bad time 'yesterday'" in err
    code, _, err = run(capsys, "export", "state", "--sim", "--config", str(recorded), "--interval", "1s")
    assert code == 1 and "aggregate time_average needs a numeric tag; state is a string" in err
