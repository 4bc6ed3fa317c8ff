"""`softplc scenario list | run | compare` and scenario files: what a user types and sees."""

from __future__ import annotations

import json
import textwrap

import pytest
from conftest import REPO

from softplc.app.cli import main
from softplc.config.yamlsource import ConfigError
from softplc.scenarios.spec import load_scenario


def cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_list_shows_every_shipped_scenario(capsys):
    code, out, _ = cli(capsys, "scenario", "list")
    assert code == 0
    for name in ("case1-sim1", "case2-sim2", "case3-sim2", "case2-sim1-optimal"):
        assert name in out
    assert "cooperative" in out and "svm" in out


def test_run_writes_records_and_prints_the_json_summary(capsys, tmp_path):
    code, out, err = cli(capsys, "scenario", "run", "case3-sim1", "--out", str(tmp_path), "--json", "--time-limit", "90",
                         "--no-figures")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["scenario"] == "case3-sim1" and summary["dispatcher"] == "svm"
    assert summary["stop_reason"] == "time limit reached" and summary["sim_duration_s"] == pytest.approx(90, abs=0.2)
    assert (tmp_path / "LEV_case3-sim1.csv").read_text().splitlines()[0].endswith("T1-D,T2-D,SVM-out")
    assert not list(tmp_path.glob("*.png"))
    assert "\r" not in err  # no progress bar when stderr is not a terminal


def test_run_shows_a_progress_bar_when_asked(capsys, tmp_path):
    code, out, err = cli(capsys, "scenario", "run", "case1-sim1", "--out", str(tmp_path), "--time-limit", "30",
                         "--no-figures", "--progress")
    assert code == 0
    assert "case1-sim1 [" in err and "100 %" in err
    assert "goals per task:" in out and "thesis:" in out


def test_run_another_dispatcher_on_the_same_plant(capsys, tmp_path):
    code, out, err = cli(capsys, "scenario", "run", "case1-sim2", "--dispatcher", "optimal", "--out", str(tmp_path),
                         "--time-limit", "60", "--no-figures", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["scenario"] == "case1-sim2-optimal" and summary["dispatcher"] == "optimal"


def test_unknown_scenario_name_suggests_the_right_one(capsys):
    code, _, err = cli(capsys, "scenario", "run", "case1-sim3")
    assert code == 1
    assert "no scenario 'case1-sim3' (did you mean 'case1-sim" in err and "shipped: " in err


def test_a_broken_scenario_file_is_reported_with_its_location(capsys, tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text(textwrap.dedent("""\
        scenario: {name: mine}
        dispatcher: {type: weighted}
        tasks:
          - {id: t01, iFr: -3, source: {x: 1, y: 1}, destination: {x: 2, y: 2}}
        robots:
          - {id: r01, start: {x: 7.9, y: 5.9}, hardware: [lazer]}
        """))
    code, _, err = cli(capsys, "scenario", "run", str(path))
    assert code == 2
    assert f"{path}:2:20: unknown type 'weighted' (did you mean 'weighting'?)" in err
    assert f"{path}:4:20: 'iFr' must be at least 0, not -3" in err
    assert f"{path}:6:51: unknown value 'lazer'" in err and "laser_range_finder" in err
    assert "3 problems found" in err


def test_a_scenario_can_extend_another(tmp_path):
    (tmp_path / "mine.yaml").write_text(textwrap.dedent(f"""\
        extends: {REPO / 'scenarios' / 'case2-sim1.yaml'}
        scenario: {{name: mine, time_limit: 100}}
        robots:
          - {{id: r01, loadcap: 5, start: {{x: 7.925, y: 5.925}}}}
        """))
    scenario = load_scenario(tmp_path / "mine.yaml")
    base = load_scenario(REPO / "scenarios" / "case2-sim1.yaml")
    assert scenario.name == "mine" and scenario.time_limit == 100 and scenario.stop == base.stop
    assert scenario.dispatcher == "cooperative" and scenario.tasks == base.tasks
    assert [robot.loadcap for robot in scenario.robots] == [5]
    assert scenario.handling_time == base.handling_time == 5


def test_a_scenario_cannot_extend_itself(tmp_path):
    (tmp_path / "a.yaml").write_text("extends: b.yaml\nscenario: {name: a}\n")
    (tmp_path / "b.yaml").write_text("extends: a.yaml\nscenario: {name: b}\n")
    with pytest.raises(ConfigError, match="extends itself"):
        load_scenario(tmp_path / "a.yaml")


def test_an_svm_scenario_without_its_model_is_refused(tmp_path):
    (tmp_path / "s.yaml").write_text(textwrap.dedent("""\
        scenario: {name: s}
        dispatcher: {type: svm, model: missing.json}
        tasks: [{id: t01, source: {x: 1, y: 1}, destination: {x: 2, y: 2}}]
        robots: [{id: r01, start: {x: 7.9, y: 5.9}}]
        """))
    with pytest.raises(ConfigError, match="no model file"):
        load_scenario(tmp_path / "s.yaml")


def test_compare_tabulates_dispatchers(capsys, tmp_path):
    code, out, err = cli(capsys, "scenario", "compare", "case1-sim1", "--time-limit", "120", "--stop", "time_limit")
    assert code == 0, err
    lines = out.strip().splitlines()
    assert lines[0].startswith("| plant | dispatcher |")
    rows = {line.split("|")[2].strip(): line for line in lines[2:]}
    assert set(rows) == {"weighting", "cooperative", "svm", "optimal"}
    assert "same as weighting" in rows["cooperative"]
    assert "—" not in rows["optimal"].split("|")[5]  # items delivered is a number


def test_an_unreachable_station_shows_as_navigation_failures(capsys, tmp_path):
    path = tmp_path / "walled.yaml"
    # task 1's source is inside the rack island in the middle of the factory map
    path.write_text(textwrap.dedent("""\
        scenario: {name: walled, time_limit: 120}
        dispatcher: {type: weighting}
        tasks:
          - {id: t01, source: {x: 12.5, y: 4.3}, destination: {x: 1.8, y: 2.5}}
        robots:
          - {id: r01, start: {x: 7.925, y: 5.925}}
        """))
    code, out, err = cli(capsys, "scenario", "run", str(path), "--out", str(tmp_path / "out"), "--no-figures")
    assert code == 0, err
    assert "navigation FAILED" in out
    summary = json.loads((tmp_path / "out" / "summary_walled.json").read_text())
    assert summary["robots"]["r01"]["navigation_failures"] >= 1
    assert summary["goals_per_task"]["t01"] == 1  # still waiting to reach the source
