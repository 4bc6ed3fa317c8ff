"""`softplc check` on the links: section and the tags' link: keys — every mistake located, all at once."""

from __future__ import annotations

import textwrap
from pathlib import Path

from softplc.adapters.links.modbus_groups import read_groups, write_runs
from softplc.adapters.links.settings import read_links
from softplc.app.cli import main
from softplc.config import load_config

GOOD = """\
plant: {name: linked}
links:
  line2:
    protocol: opcua
    endpoint: opc.tcp://127.0.0.1:4841/softplc/
    period: 50ms
  press:
    protocol: modbus
    host: 127.0.0.1
    port: 5021
    word_order: little
tags:
  ready: {type: bool, link: {name: line2, source: "ns={ns};s=Ready", direction: both}}
  force: {type: float32, access: ro, link: {name: press, source: "holding:100", type: int16, scale: 10}}
  count: {type: uint32, link: {name: press, source: "input:0"}}
  speed: {type: float32, link: {name: press, source: "holding:101", direction: out}}
  name: {type: string, link: {name: press, source: "holding:200", words: 4}}
  lamp: {type: bool, link: {name: press, source: "coil:3", direction: both}}
"""


def check(tmp_path: Path, text: str, capsys) -> tuple[int, list[str]]:
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(text))
    code = main(["check", str(path)])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, [line.removeprefix(f"{path}:") for line in err.splitlines() if line.startswith(str(path))]


def test_a_plant_with_links_checks_clean_and_reads_its_bindings(tmp_path: Path, capsys) -> None:
    code, lines = check(tmp_path, GOOD, capsys)
    assert (code, lines) == (0, [])
    links = read_links(load_config(tmp_path / "tagdb.yaml"))
    assert links.problems == []
    line2, press = links.links["line2"], links.links["press"]
    assert (line2.protocol, line2.period, line2.endpoint) == ("opcua", 0.05, "opc.tcp://127.0.0.1:4841/softplc/")
    assert (press.host, press.port, press.unit, press.word_order) == ("127.0.0.1", 5021, 1, "little")
    bindings = {b.name: b for b in press.bindings}
    assert bindings["force"].codec is not None and bindings["force"].codec.scale == 10.0
    assert bindings["count"].size == 2 and bindings["count"].codec.word_order == "little"  # type: ignore[union-attr]
    assert bindings["name"].size == 4 and bindings["lamp"].codec is None
    assert [b.direction.value for b in line2.bindings] == ["both"]


def test_every_mistake_is_reported_where_it_is_written(tmp_path: Path, capsys) -> None:
    code, lines = check(tmp_path, """\
        plant: {name: linked}
        links:
          plc2:
            protocol: opcua
            endpoint: http://127.0.0.1:4841/
            host: 10.0.0.1
          press:
            protocol: modbus
            host: 127.0.0.1
            period: soon
        tags:
          a: {type: bool, link: {name: plc3, source: "ns=2;s=A"}}
          b: {type: float32, link: {name: plc2, source: "ns={ns};s=B", scale: 3}}
          c: {type: float32, link: {name: press, source: "holding:100", type: int16, scale: 10}}
          d: {type: int16, link: {name: press, source: "holding:100"}}
          e: {type: int16, link: {name: press, source: "input:5", direction: out}}
          f: {type: int32, link: {name: press, source: "coil:5"}}
          g: {type: int16, link: {name: press, source: "holdng:5"}}
          h: {type: string, link: {name: press, source: "holding:200", words: 4}}
          i: {type: int16, link: {name: press, source: "holding:202"}}
          j: {type: int16, link: {name: plc2, source: "ns=2;x=J"}}
          k: {type: int16, link: {name: press, source: "holding:300", type: float32}}
        """, capsys)
    assert code == 2
    text = "\n".join(lines)
    for expected in (
        "5:15: link plc2 needs endpoint: opc.tcp://HOST:PORT[/PATH], not 'http://127.0.0.1:4841/'",
        "6:11: host is for a Modbus link; link plc2 is opcua",
        "10:13: bad period 'soon'",
        "12:32: unknown link 'plc3' (did you mean 'plc2'?) (links: plc2, press)",
        "13:71: scale is for a Modbus register; link plc2 is OPC UA",
        "15:48: register overlap on link press: d at holding:100 overlaps c (holding:100..100)",
        "16:70: input registers are read-only in Modbus: direction out needs a coil or holding register",
        "17:48: a coil is one bit: tag f must be bool, not int32",
        "18:48: bad register 'holdng:5' (did you mean 'holding'?)",
        "20:48: register overlap on link press: i at holding:202 overlaps h (holding:200..203)",
        "21:47: bad node id 'ns=2;x=J'",
        "22:69: tag k is int16: a float32 register needs the tag to be a float too (or a scale)",
    ):
        assert expected in text, f"missing {expected!r} in:\n{text}"
    assert len(lines) == 12


def test_a_register_inside_a_longer_value_is_an_overlap_too(tmp_path: Path, capsys) -> None:
    code, lines = check(tmp_path, """\
        links:
          press: {protocol: modbus, host: 127.0.0.1}
        tags:
          long: {type: float64, link: {name: press, source: "holding:0"}}
          short: {type: int16, link: {name: press, source: "holding:1"}}
          later: {type: int16, link: {name: press, source: "holding:3"}}
        """, capsys)
    assert code == 2
    assert len(lines) == 2 and "short at holding:1 overlaps long (holding:0..3)" in lines[0] and "later at holding:3" in lines[1]


def test_the_section_adds_diagnostic_tags_and_a_down_alarm_per_link(tmp_path: Path) -> None:
    from softplc.config.sections import contributed_alarms

    (tmp_path / "tagdb.yaml").write_text(GOOD)
    config = load_config(tmp_path / "tagdb.yaml")
    names = [tag.name for tag in config.contributed_tags if tag.name.startswith("_sys.links.")]
    assert names == [f"_sys.links.{link}.{key}" for link in ("line2", "press")
                     for key in ("connected", "state", "error", "bad_tags", "reconnects", "round_trip_ms")]
    alarms = {spec["name"]: (path, spec) for path, spec in contributed_alarms(config)}
    path, spec = alarms["link_press_down"]
    assert path == ("links", "press") and spec["discrete"] == {"tag": "_sys.links.press.connected", "value": False}


def test_reads_are_grouped_over_contiguous_registers_and_writes_in_runs(tmp_path: Path) -> None:
    lines = ["links:", "  press: {protocol: modbus, host: 127.0.0.1}", "tags:"]
    # 300 int16 at 0..299, a float32 at 300..301, a gap, then 400..409; two coils.
    lines += [f"  r{i}: {{type: int16, link: {{name: press, source: 'holding:{i}'}}}}" for i in range(300)]
    lines += ["  f: {type: float32, link: {name: press, source: 'holding:300'}}"]
    lines += [f"  s{i}: {{type: int16, link: {{name: press, source: 'holding:{400 + i}', direction: both}}}}" for i in range(10)]
    lines += ["  c0: {type: bool, link: {name: press, source: 'coil:0'}}", "  c1: {type: bool, link: {name: press, source: 'coil:1'}}"]
    (tmp_path / "tagdb.yaml").write_text("\n".join(lines) + "\n")
    press = read_links(load_config(tmp_path / "tagdb.yaml")).links["press"]
    groups = read_groups(press.bindings)
    assert [(g.table, g.start, g.count) for g in groups] == [("coil", 0, 2), ("holding", 0, 125), ("holding", 125, 125),
                                                             ("holding", 250, 52), ("holding", 400, 10)]
    # With a gap allowed, f (300..301) and s0..s9 (400..409) are 98 unbound registers apart.
    apart = [b for b in press.bindings if b.name == "f" or b.name.startswith("s")]
    assert [(g.start, g.count) for g in read_groups(apart, gap=98)] == [(300, 110)]
    assert [(g.start, g.count) for g in read_groups(apart, gap=97)] == [(300, 2), (400, 10)]
    assert [(g.start, g.count) for g in read_groups(apart, gap=98, max_registers=100)] == [(300, 2), (400, 10)]
    by_name = {b.name: b for b in press.bindings}
    batch = [(by_name["s3"], [3]), (by_name["s1"], [1]), (by_name["s2"], [2]), (by_name["r5"], [5]), (by_name["c1"], [True])]
    runs = write_runs(batch)
    assert [(r.table, r.start, r.values, r.items) for r in runs] == [("holding", 5, (5,), (3,)), ("holding", 401, (1, 2, 3), (1, 2, 0)),
                                                                     ("coil", 1, (True,), (4,))]
