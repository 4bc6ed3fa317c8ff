"""Mistakes in the alarms: section are located problems of `softplc check` (FILE:LINE:COL), all at once."""

from __future__ import annotations

import re

from softplc.app.cli import main
from tests.alarms_support import PLANT, plant

MISTAKES = """
definitions:
  - name: "{task}_full"
    for_each: task
    limit: {tag: "{task}_iBX", hi: 95}
  - name: lvl
    limit: {tag: level, hi: 90, hihi: 80}
  - name: nav
    discrete: {tag: navstate, value: failed, normal: idle}
  - name: cond
    condition: level > 3 and levle < 5
  - name: msg
    limit: {tag: level, lo: 1}
    message: "{levl:.1f} is low"
  - name: lvl
    condition: flag
  - name: bad-name
    condition: flag
  - name: twice
    condition: flag
    discrete: {tag: flag, value: true}
  - name: txt
    limit: {tag: navstate, hi: 1}
  - name: slow
    condition: flag
    on_delay: 10 parsecs
  - name: "{robot}_x"
    for_each: robot
    condition: flag
  - name: pct
    limit: {tag: t01_iBL, hi: 120}
  - name: fmt
    condition: flag
    message: "{navstate:.2f}"
journal: {backend: postgresql}
"""

EXPECTED = [  # (line in the alarms: section counted from 1 at 'definitions:', text in the message)
    (4, "no tag 't01_iBX' (did you mean 't01_iBL'?) (for_each: task; the same in 1 other instance(s))"),
    (6, "hihi 80 must be above hi 90"),
    (8, "a discrete alarm needs exactly one of value"),
    (10, "unknown tag 'levle' in condition (did you mean 'level'?)"),
    (13, "unknown placeholder {levl} in message: not a tag (did you mean 'level'?)"),
    (14, "duplicate alarm name 'lvl' (also at"),
    (16, "invalid alarm name 'bad-name'"),
    (18, "alarm 'twice' needs exactly one of limit, discrete, condition, increase (it has discrete and condition)"),
    (22, "a limit alarm needs a numeric tag; navstate is string"),
    (25, "bad on_delay '10 parsecs'"),
    (27, "for_each must name a template; 'robot' is not one"),
    (30, "hi 120 is above the max 100 of t01_iBL: the alarm could never be active"),
    (33, "placeholder {navstate:.2f}"),
    (34, "backend postgresql needs a dsn"),
]


def test_every_mistake_is_located_at_once(tmp_path, capsys) -> None:
    path = tmp_path / "tagdb.yaml"
    text = plant(MISTAKES)
    path.write_text(text)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    first = text.splitlines().index("alarms:") + 1  # 'definitions:' is the line after, 1-based
    problems = {int(match.group(1)): match.group(2) for match in re.finditer(rf"^{re.escape(str(path))}:(\d+):\d+: (.*)$", err, re.M)}
    for line, text_part in EXPECTED:
        assert text_part in problems.get(first + line, ""), (first + line, text_part, err)
    assert f"{len(EXPECTED)} problems found" in err


def test_a_good_section_checks_ok_with_its_summary_tags(tmp_path, capsys) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(plant("""
        shelve_max: 2h
        journal: {retention: 30d}
        definitions:
          - name: "{task}_input_full"
            for_each: task
            limit: {tag: "{task}_iBL", hi: {limit: 95, priority: high}, hihi: {limit: 99, priority: critical}, deadband: 5}
            message: "Input buffer of {task} is {value:.0f} % full"
          - {name: overruns, increase: {tag: _sys.scan.overruns, within: 60s}, priority: low}
        """))
    assert main(["check", str(path)]) == 0, capsys.readouterr().err
    assert main(["tags", str(path), "--format", "csv"]) == 0
    out = capsys.readouterr().out
    for name in ("_sys.alarms.active", "_sys.alarms.unacknowledged", "_sys.alarms.highest_priority", "_sys.alarms.shelved"):
        assert f"{name},uint" in out
    assert "_sys.alarms.acknowledge_all,bool,False,,rw" in out


def test_a_plant_without_alarms_gets_no_summary_tags(tmp_path, capsys) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(PLANT)
    assert main(["tags", str(path), "--format", "csv"]) == 0
    assert "_sys.alarms." not in capsys.readouterr().out


def test_the_schema_locates_a_structural_mistake(tmp_path, capsys) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(plant("definitions:\n  - {name: x, condition: flag, priorty: high}"))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'priorty' (did you mean 'priority'?)" in err
