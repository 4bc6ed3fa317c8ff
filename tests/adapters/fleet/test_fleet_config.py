"""Robot/task configuration, the tie to tagdb.yaml, compatibility (thesis Tables 6 and 7), `softplc compat`."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
from conftest import REPO

from softplc.adapters.fleet import Compatibility, Hardware, compatibility_matrix, compatible, load_robots, load_tasks
from softplc.app.cli import main
from softplc.config import load_config
from softplc.config.yamlsource import ConfigError
from softplc.robotics.robots import DriverKind, parse_robots, parse_tasks

ROBOTS = REPO / "robots"


def problems(error: pytest.ExceptionInfo[ConfigError]) -> list[tuple[int, int, str]]:
    return [(p.location.line, p.location.column, p.message) for p in error.value.problems]


def test_default_robots_and_tasks_load() -> None:
    robots = load_robots(ROBOTS / "robots.yaml")
    assert robots.ids == ["r01", "r02", "r03"]
    r01 = robots["r01"]
    assert (r01.start.x, r01.start.y) == (7.925, 5.925)
    assert r01.max_linear_speed == 0.2 and r01.max_angular_speed == 0.4
    assert r01.driver is DriverKind.SIM and Hardware.GRIPPER in r01.hardware
    assert r01.radius == pytest.approx(0.5 * (255**2 + 255**2) ** 0.5 / 1000)
    tasks = load_tasks(ROBOTS / "tasks.yaml")
    assert [(t.source.x, t.source.y, t.destination.x, t.destination.y) for t in tasks] == [(3.5, 7.5, 1.8, 2.5), (18.5, 7.5, 20.1, 2.4)]


ROBOT = """\
robots:
  - id: r01
    length_mm: 255
    width_mm: 255
    height_mm: 400
    load_capacity: 20
    max_linear_speed: 0.2
    max_angular_speed: 0.4
    hardware: [laser_rangefinder, gripper]
    start: {x: 1, y: 2}
    driver: simulated
  - id: r01
    length_mm: 255
    width_mm: "wide"
    height_mm: 400
    load_capacity: 20
    max_linear_speed: 0
    max_angular_speed: 0.4
    start: {x: 1}
"""


def test_robot_file_errors_are_located_with_hints() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_robots(ROBOT, "robots.yaml")
    assert problems(caught) == [
        (9, 16, "unknown value 'laser_rangefinder' for item 1 of 'hardware' (did you mean 'laser_range_finder'?); "
         "expected one of: laser_range_finder, camera, two_wheel_drive, sonar, gripper"),
        (11, 13, "unknown value 'simulated' for 'driver'; expected one of: sim, remote, vda5050"),
        (14, 15, "'width_mm' must be a number, not string 'wide'"),
        (17, 23, "'max_linear_speed' must be more than 0, not 0"),
        (19, 5, "'start' is missing the required key 'y'"),
    ]
    assert str(caught.value).startswith("robots.yaml:")


def test_duplicate_ids_and_unknown_keys() -> None:
    text = ROBOT.replace("laser_rangefinder", "laser_range_finder").replace("simulated", "sim")
    text = text.replace('"wide"', "255").replace("max_linear_speed: 0\n", "max_linear_speed: 0.3\n").replace("{x: 1}", "{x: 1, y: 1}")
    with pytest.raises(ConfigError) as caught:
        parse_robots(text, "robots.yaml")
    assert problems(caught) == [(12, 9, "duplicate id 'r01' (first used at line 2)")]
    with pytest.raises(ConfigError) as caught:
        parse_tasks("tasks:\n  - id: t01\n    max_lenght_mm: 1\n", "tasks.yaml")
    assert any("unknown key 'max_lenght_mm' (did you mean 'max_length_mm'?)" in m for _, _, m in problems(caught))


def test_tagdb_robot_tags_come_from_robots_yaml() -> None:
    config = load_config(REPO / "tagdb.yaml")
    assert config.instances["robot"] == ["r01", "r02", "r03"]
    initial = {d.name: d.initial for d in config.tags}
    for robot in load_robots(ROBOTS / "robots.yaml"):
        assert initial[f"{robot.id}_xpos"] == robot.start.x == initial[f"{robot.id}_xgoal"]
        assert initial[f"{robot.id}_ypos"] == robot.start.y == initial[f"{robot.id}_ygoal"]
        assert initial[f"{robot.id}_navstate"] == "idle"
    assert config.raw["fleet"]["map"] == "robots/maps/factory.yaml"


TAGDB = """\
version: 1
templates:
  robot:
    instances_from:
      file: {file}
      initial: {{xpos: start.x, ypos: {ypath}}}
    tags:
      xpos: {{type: float64}}
      ypos: {{type: float64}}
"""


def write(directory: Path, name: str, text: str) -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text))
    return path


def test_instances_from_adds_a_robot_by_editing_robots_yaml_only(tmp_path: Path) -> None:
    robots = (ROBOTS / "robots.yaml").read_text() + (
        "  - {id: r04, length_mm: 255, width_mm: 255, height_mm: 400, load_capacity: 5,\n"
        "     max_linear_speed: 0.2, max_angular_speed: 0.4, start: {x: 3, y: 4}}\n"
    )
    write(tmp_path, "robots.yaml", robots)
    config = load_config(write(tmp_path, "tagdb.yaml", TAGDB.format(file="robots.yaml", ypath="start.y")))
    assert config.instances["robot"] == ["r01", "r02", "r03", "r04"]
    assert config.tag("r04_xpos").initial == 3.0 and config.tag("r04_ypos").initial == 4.0


def test_instances_from_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as caught:
        load_config(write(tmp_path, "tagdb.yaml", TAGDB.format(file="nowhere.yaml", ypath="start.y")))
    assert problems(caught) == [(5, 13, f"instances_from: file not found: {tmp_path / 'nowhere.yaml'}")]
    write(tmp_path, "robots.yaml", "robots:\n  - {id: r01, start: {x: 1, y: 2}}\n  - {name: nameless}\n  - {id: 9lives}\n")
    with pytest.raises(ConfigError) as caught:
        load_config(write(tmp_path, "tagdb.yaml", TAGDB.format(file="robots.yaml", ypath="start.why")))
    found = [(str(p.location), p.message) for p in caught.value.problems]
    robots_file = str(tmp_path / "robots.yaml")
    assert (f"{robots_file}:3:5", "item 2 cannot be an instance of template 'robot': it has no 'id'") in found
    assert (f"{robots_file}:4:5", "item 3 cannot be an instance of template 'robot': its id '9lives' is not a valid name "
            "(ASCII letters, digits and _, not starting with a digit)") in found
    assert (f"{tmp_path / 'tagdb.yaml'}:6:38", f"no item of {robots_file} has 'start.why'") in found


# -- compatibility: thesis Tables 6 and 7 are the test vectors -------------------------------


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        ("case2-sim1", {"r01": {"t01": True, "t02": True}, "r02": {"t01": False, "t02": True}}),
        ("case2-sim2", {"r01": {"t01": True, "t02": False}, "r02": {"t01": False, "t02": True}, "r03": {"t01": True, "t02": True}}),
    ],
)
def test_thesis_compatibility_tables(case: str, expected: dict[str, dict[str, bool]]) -> None:
    compat = Compatibility.load(ROBOTS / case / "robots.yaml", ROBOTS / case / "tasks.yaml")
    assert compat.matrix() == expected
    assert compatibility_matrix(compat.robots, compat.tasks) == expected
    for robot_id, row in expected.items():
        assert compat.tasks_for(robot_id) == [t for t, ok in row.items() if ok]
        for task_id, ok in row.items():
            assert compat.check(robot_id, task_id) is ok
            assert compatible(compat.robot(robot_id), compat.task(task_id)) is ok
            assert (compat.why_not(robot_id, task_id) == []) is ok
    for task_id in ("t01", "t02"):
        assert compat.robots_for(task_id) == [r for r, row in expected.items() if row[task_id]]


def test_each_rule_can_break_compatibility() -> None:
    compat = Compatibility.load(ROBOTS / "case2-sim2" / "robots.yaml", ROBOTS / "case2-sim2" / "tasks.yaml")
    # Table 7: R-01 misses task 2 on load, both speeds, camera and sonar; R-02 misses task 1 on size.
    assert compat.why_not("r01", "t02") == ["load capacity 0.5 < 10", "linear speed 0.5 m/s < 2 m/s",
                                             "angular speed 1 rad/s < 2 rad/s", "no camera", "no sonar"]
    assert compat.why_not("r02", "t01") == ["length 500 mm > 400 mm", "width 600 mm > 500 mm", "height 700 mm > 600 mm"]
    with pytest.raises(KeyError, match="no robot 'r9'.*known: r01, r02, r03"):
        compat.check("r9", "t01")


def test_compat_command_table_and_json(capsys: pytest.CaptureFixture[str]) -> None:
    case = ROBOTS / "case2-sim1"
    assert main(["compat", "--robots", str(case / "robots.yaml"), "--tasks", str(case / "tasks.yaml")]) == 0
    table = capsys.readouterr().out
    assert "r01    R-01  yes  yes  t01, t02" in table and "r02    R-02  no   yes  t02" in table
    assert "r02 cannot serve t01: length 500 mm > 400 mm" in table
    assert main(["compat", "--robots", str(case / "robots.yaml"), "--tasks", str(case / "tasks.yaml"), "--format", "json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["robots"] == {"r01": ["t01", "t02"], "r02": ["t02"]}
    assert document["tasks"] == {"t01": ["r01"], "t02": ["r01", "r02"]}


def test_compat_command_reports_config_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = write(tmp_path, "robots.yaml", "robots:\n  - id: r01\n")
    assert main(["compat", "--robots", str(bad), "--tasks", str(ROBOTS / "tasks.yaml")]) == 2
    assert f"{bad}:2:5: " in capsys.readouterr().err
