"""`servers: hmi:` and `hmi: views:` in tagdb.yaml: every mistake a located problem of `softplc check`."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest
from hmi_support import REPO, plant_yaml, write_plant

from softplc.adapters.hmi.settings import HmiSettings, hmi_problems
from softplc.app.adapters import build_adapters
from softplc.app.cli import main
from softplc.config import load_config
from softplc.config.yamlsource import ConfigError
from softplc.core.roles import Role

BAD_VIEW = """
hmi:
  views:
    test:
      svg: view.svg
      bindings:
        levle: {bar: {tag: t01_iBL}}
        items: {text: {tag: t01_iBN}}
        sum:   {text: "t01_iBM + t02_iBX"}
        alarm: {visible: "t01_iBL >= import os"}
        tank:  {fill: {tag: t01_iBL, on_color: "red; background: url(x)"}}
        button: {click: {tag: limit, write: 500}}
        robot: {bar: {tag: t01_iBL}}
"""


def problems_of(tmp_path: Path, text: str) -> list[str]:
    if not (tmp_path / "view.svg").exists():
        write_plant(tmp_path)
    path = tmp_path / "tagdb.yaml"
    path.write_text(text)
    try:
        config = load_config(path)
    except ConfigError as error:
        return [str(problem) for problem in error.problems]
    return [str(problem) for problem in hmi_problems(config)]


def replace_views(text: str) -> str:
    return text[: text.index("hmi:\n  views:")] + BAD_VIEW.lstrip()


def test_the_default_plant_and_its_example_view_are_valid() -> None:
    config = load_config(REPO / "tagdb.yaml")
    assert hmi_problems(config) == []
    settings = HmiSettings.from_config(config)
    assert (settings.host, settings.port, settings.anonymous_role) == ("127.0.0.1", 8080, Role.VIEWER)


def test_every_mistake_of_a_view_is_reported_with_its_line(tmp_path: Path) -> None:
    text = replace_views(plant_yaml())
    found = problems_of(tmp_path, text)
    lines = text.splitlines()

    def at(message: str, needle: str) -> None:
        matches = [problem for problem in found if message in problem]
        assert matches, (message, found)
        line = int(matches[0].split(":")[1])
        assert needle in lines[line - 1], (matches[0], lines[line - 1])

    at("the SVG has no element with id 'levle' (did you mean 'level'?)", "levle:")
    at("unknown tag 't01_iBN' (did you mean 't01_iBM'?)", "items:")
    at("unknown tag 't02_iBX' in expression", "sum:")
    at("cannot parse", "alarm:")
    at("not a colour: 'red; background: url(x)'", "tank:")
    at("500.0 is above the maximum 100 (tag limit)", "button:")
    at("a bar must be a <rect>, but 'robot' is a <g>", "robot:")
    assert len(found) == 7, found


def test_softplc_check_reports_view_problems_and_fails(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_plant(tmp_path, replace_views(plant_yaml()))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'level'?" in err and "7 problems found" in err


def test_a_missing_or_broken_drawing_is_a_problem(tmp_path: Path) -> None:
    path = write_plant(tmp_path)
    (tmp_path / "view.svg").write_text("<svg><rect id='a'></svg>")
    assert any("view.svg is not well-formed XML: mismatched tag at line 1" in problem for problem in problems_of(tmp_path, path.read_text()))
    (tmp_path / "view.svg").write_text("<html><body/></html>")
    assert any("is not an SVG drawing (its root element is <html>)" in problem for problem in problems_of(tmp_path, path.read_text()))
    text = path.read_text().replace("svg: view.svg", "svg: missing.svg")
    assert any("SVG file not found" in problem for problem in problems_of(tmp_path, text))


def test_server_settings_are_checked(tmp_path: Path) -> None:
    text = plant_yaml().replace("    host: 127.0.0.1\n", "    host: 'bad host'\n").replace("    port: 0\n", "    port: 0\n    heartbeat: 10 parsecs\n    session_timeout: 1s\n"
                                "    allowed_origins: [scada.example.com]\n    tls: {certificate: none.pem, private_key: none.key}\n    colour: blue\n")
    found = problems_of(tmp_path, text)
    joined = "\n".join(found)
    assert "unknown key 'colour'" in joined
    text = text.replace("    colour: blue\n", "")
    joined = "\n".join(problems_of(tmp_path, text))
    for message in ("bad heartbeat '10 parsecs'", "session_timeout must be between 60 s", "not an IP address or host name: 'bad host'",
                    "an origin looks like https://host[:port], not 'scada.example.com'", "certificate file not found"):
        assert message in joined, (message, joined)


def test_flags_override_the_file_and_no_hmi_leaves_it_out(tmp_path: Path) -> None:
    config = load_config(write_plant(tmp_path))
    args = argparse.Namespace(hmi_host="127.0.0.2", hmi_port=8123, hmi_anonymous="off", hmi_tls=None, hmi_open=False, no_hmi=False,
                              no_servers=False, no_opcua=True, no_modbus=True, no_fleet=True)
    (hmi,) = [adapter for adapter in build_adapters(config, args) if adapter.name == "hmi"]
    assert (hmi.settings.host, hmi.settings.port, hmi.settings.anonymous_role) == ("127.0.0.2", 8123, None)
    args.no_hmi = True
    assert not [adapter for adapter in build_adapters(config, args) if adapter.name == "hmi"]


def test_anonymous_viewers_only_on_loopback_unless_configured() -> None:
    assert HmiSettings(host="127.0.0.1").anonymous_role is Role.VIEWER
    assert HmiSettings(host="0.0.0.0").anonymous_role is None
    assert HmiSettings(host="0.0.0.0", anonymous="viewer").anonymous_role is Role.VIEWER
    assert HmiSettings(host="127.0.0.1", anonymous="off").anonymous_role is None


def test_softplc_run_prints_where_the_hmi_serves(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_plant(tmp_path)
    code = main(["run", str(path), "--sim", "--speed", "20", "--duration", "20", "--no-status", "--state-dir", str(tmp_path / "state"),
                 "--hmi-port", "0", "--no-opcua", "--no-modbus", "--no-fleet"])
    err = capsys.readouterr().err
    assert code == 0, err
    line = next(line for line in err.splitlines() if line.startswith("serving: HMI on "))
    assert line.startswith("serving: HMI on http://127.0.0.1:") and "open it in a browser" in line
