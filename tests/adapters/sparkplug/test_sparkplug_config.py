"""The `sparkplug:` section: devices by template and pattern, aliases, read-only by role, and located mistakes."""

from __future__ import annotations

from pathlib import Path

import pytest

from softplc.adapters.sparkplug.settings import SparkplugSettings
from softplc.app.cli import main
from softplc.config.yamlsource import ConfigError
from softplc.core.roles import Role

PLANT = """
version: 1
plant: {name: line1}
templates:
  robot:
    instances: [r01, r02]
    tags:
      xpos: {type: float64, unit: m, access: ro}
      goal: {type: float64, min: 0, max: 20}
tags:
  level: {type: float32}
  panel_light: {type: bool}
"""


def test_the_default_is_a_device_per_template_instance_and_one_for_the_other_tags(make_config) -> None:
    settings = SparkplugSettings.from_config(make_config(PLANT + "sparkplug: {group_id: plant1}\n"))
    assert (settings.group_id, settings.edge_node_id, settings.primary_host, settings.role) == ("plant1", "line1", None, Role.OPERATOR)
    assert [(d.id, [m.name for m in d.metrics.values()]) for d in settings.devices] == [
        ("r01", ["xpos", "goal"]), ("r02", ["xpos", "goal"]), ("plant", ["level", "panel_light"])]
    aliases = [m.alias for d in settings.devices for m in d.metrics.values()]
    assert aliases == list(range(1, 7))  # unique across the node, stable for one configuration
    r01 = settings.devices[0].metrics
    assert (r01["r01_xpos"].unit, r01["r01_xpos"].read_only, r01["r01_goal"].high, r01["r01_goal"].read_only) == ("m", True, 20, False)


def test_devices_by_pattern_with_a_role_and_system_tags_only_when_asked(make_config) -> None:
    settings = SparkplugSettings.from_config(make_config(PLANT + """
sparkplug:
  group_id: plant1
  edge_node_id: edge
  aliases: false
  commands: {role: engineer, user: scada-1, clock_tolerance: 500ms}
  devices:
    - {template: robot, id: "robot-{instance}"}
    - {id: panel, tags: "panel_*", role: viewer}
    - {id: rest, tags: ["*"]}
    - {id: diagnostics, tags: "_sys.fast.*"}
tasks:
  fast: {interval: 10ms}
"""))
    devices = {d.id: d for d in settings.devices}
    assert list(devices) == ["robot-r01", "robot-r02", "panel", "rest", "diagnostics"]
    assert devices["panel"].role is Role.VIEWER and devices["panel"].metrics["panel_light"].read_only
    assert devices["robot-r01"].metrics["r01_xpos"].read_only is False  # an engineer may write ro tags
    assert list(devices["rest"].metrics) == ["level"]  # '*' takes no _sys. tag, and nothing already claimed
    assert "_sys.fast.cycles" in devices["diagnostics"].metrics and all(not n.startswith("_sys.sparkplug.") for n in devices["diagnostics"].metrics)
    assert all(m.alias is None for d in settings.devices for m in d.metrics.values())
    assert (settings.user, settings.clock_tolerance) == ("scada-1", 0.5)


@pytest.mark.parametrize(("section", "expected"), [
    ("{group_id: plant/1}", ":2: group_id 'plant/1' contains '/'"),
    ("{group_id: g, edge_node_id: 'a+b'}", ":2: edge_node_id 'a+b' contains '+'"),
    ("{group_id: g, devices: [{template: robots}]}", ":2: unknown template 'robots' (did you mean 'robot'?)"),
    ("{group_id: g, devices: [{template: robot, id: bot}]}", ":2: the id of a template's devices must contain {instance}"),
    ("{group_id: g, devices: [{id: x, tags: 'conveyor_*'}]}", ":2: the patterns 'conveyor_*' match no tag"),
    ("{group_id: g, devices: [{template: robot, tags: '*'}]}", ":2: a device names either a 'template'"),
    ("{group_id: g, devices: [{id: a, tags: 'level'}, {id: a, tags: 'panel_*'}]}", ":2: device id 'a' is used twice"),
    ("{group_id: g, store: {max_size: 1KB}}", ":2: max_size '1KB' is too small for the store"),
    ("{group_id: g, commands: {clock_tolerance: soon}}", ":2: bad clock_tolerance 'soon'"),
    ("{edge_node_id: x}", ":2: 'sparkplug' is missing the required key 'group_id'"),
])
def test_mistakes_are_located(tmp_path: Path, section: str, expected: str) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text("version: 1\nsparkplug: " + section + "\n" + PLANT.replace("version: 1\n", "", 1))
    with pytest.raises(ConfigError) as caught:
        from softplc.config import load_config

        load_config(path)
    line, message = expected.split(": ", 1) if expected.startswith(":") else ("", expected)
    assert any(f"{path}{line}:" in str(problem) and message in str(problem) for problem in caught.value.problems), \
        [str(p) for p in caught.value.problems]


def test_check_prints_the_problem_with_its_place(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(PLANT + "sparkplug:\n  group_id: g\n  devices:\n    - {template: robots}\n")
    assert main(["check", str(path)]) == 2
    assert f"{path}:16:18: unknown template 'robots' (did you mean 'robot'?)" in capsys.readouterr().err


def test_the_status_tags_and_alarms_come_with_the_section(make_config) -> None:
    config = make_config(PLANT + "sparkplug: {group_id: g, primary_host: scada}\n")
    names = [tag.name for tag in config.contributed_tags if tag.name.startswith("_sys.sparkplug.")]
    assert {"_sys.sparkplug.state", "_sys.sparkplug.connected", "_sys.sparkplug.primary_host_online", "_sys.sparkplug.stored"} <= set(names)
    from softplc.config.sections import contributed_alarms

    alarms = {definition["name"]: definition for _, definition in contributed_alarms(config)}
    assert set(alarms) == {"sparkplug_disconnected", "sparkplug_primary_host_offline"}
    assert alarms["sparkplug_disconnected"]["suppress_when"] == "not _sys.sparkplug.running"
    assert not [a for _, a in contributed_alarms(make_config(PLANT)) if a["name"].startswith("sparkplug")]
