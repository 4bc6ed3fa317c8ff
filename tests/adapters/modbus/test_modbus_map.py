"""The Modbus address map: allocation rule, stability, overrides, config errors, codec, CLI."""

from __future__ import annotations

import csv
import io
import json
import math
import struct

import pytest

from softplc.adapters.modbus.address_map import Table, build_address_map
from softplc.app.cli import main
from softplc.config.yamlsource import ConfigError
from softplc.core.datatypes import DataType
from softplc.protocols.modbus_codec import CodecError, RegisterCodec

BASE = """
version: 1
templates:
  robot:
    instances: [r01, r02]
    tags:
      busy: {type: bool}
      xpos: {type: float64, access: ro}
      goal: {type: uint16}
tags:
  run:     {type: bool}
  alarm:   {type: bool, access: ro}
  speed:   {type: float32}
  total:   {type: uint32, access: ro}
  name:    {type: string}
"""


def placed(address_map, name):
    mapping = address_map.by_tag[name]
    return mapping.table.value, mapping.address, mapping.words


def test_default_tables_and_packing_in_declaration_order(make_config):
    m = build_address_map(make_config(BASE))
    # templates first (instance by instance), then plain tags — the order `softplc tags` lists
    assert placed(m, "r01_busy") == ("coil", 0, 1)
    assert placed(m, "r02_busy") == ("coil", 1, 1)
    assert placed(m, "run") == ("coil", 2, 1)
    assert placed(m, "alarm") == ("discrete_input", 0, 1)
    assert placed(m, "r01_xpos") == ("input", 0, 4)
    assert placed(m, "r02_xpos") == ("input", 4, 4)
    assert placed(m, "total") == ("input", 8, 2)
    assert placed(m, "r01_goal") == ("holding", 0, 1)
    assert placed(m, "r02_goal") == ("holding", 1, 1)
    assert placed(m, "speed") == ("holding", 2, 2)
    assert placed(m, "name") == ("holding", 4, 16)  # default string_words
    mapping = m.by_tag["speed"]
    assert (mapping.number, mapping.reference) == (3, "40003")
    assert m.by_tag["alarm"].reference == "10001"


def test_system_tags_live_in_their_own_block(make_config):
    m = build_address_map(make_config(BASE + "tasks:\n  fast: {interval: 10ms}\n"))
    system = [mapping for mapping in m.mappings if mapping.name.startswith("_sys.")]
    assert system and all(mapping.address >= 60000 for mapping in system)
    assert placed(m, "_sys.reset_stats") == ("coil", 60000, 1)
    assert m.by_tag["_sys.state"].table is Table.INPUT and m.by_tag["_sys.state"].address == 60000
    assert m.by_tag["_sys.fast.cycles"].table is Table.INPUT
    quiet = build_address_map(make_config(BASE + "servers:\n  modbus: {system_tags: false}\n"))
    assert not [mapping for mapping in quiet.mappings if mapping.name.startswith("_sys.")]


def test_adding_tags_at_the_end_or_pinned_moves_nothing(make_config):
    before = build_address_map(make_config(BASE))
    after = build_address_map(make_config(BASE + "  extra: {type: float64}\n  flag2: {type: bool}\n  pin: {type: int16, modbus: {address: 1000}}\n"))
    for mapping in before.mappings:
        assert placed(after, mapping.name) == placed(before, mapping.name), mapping.name
    assert placed(after, "extra") == ("holding", 20, 4)
    assert placed(after, "pin") == ("holding", 1000, 1)
    # and the map is the same on every load (stable across restarts)
    again = build_address_map(make_config(BASE))
    assert [placed(again, m.name) for m in again.mappings] == [placed(before, m.name) for m in before.mappings]


def test_overrides_table_address_encoding(make_config):
    m = build_address_map(make_config("""
        version: 1
        tags:
          level:  {type: float32, modbus: {scale: 100}}
          big:    {type: float64, modbus: {register_type: int32, scale: 10, word_order: little}}
          ro_h:   {type: uint16, access: ro, modbus: {table: holding, address: 200}}
          flag:   {type: bool, modbus: {table: input}}
          label:  {type: string, modbus: {words: 3}}
          off:    {type: int16, modbus: {enabled: false}}
        servers:
          modbus: {word_order: little, string_words: 8, system_tags: false}
    """))
    assert placed(m, "level") == ("holding", 0, 1) and m.by_tag["level"].encoding == "int16 x100"
    assert placed(m, "big") == ("holding", 1, 2) and m.by_tag["big"].codec.word_order == "little"
    assert placed(m, "ro_h") == ("holding", 200, 1)
    assert placed(m, "flag") == ("input", 0, 1)
    assert placed(m, "label") == ("holding", 3, 3)
    assert "off" not in m.by_tag


def expect_problems(make_config, text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        build_address_map(make_config(text))
    return [str(problem) for problem in caught.value.problems]


def test_overlapping_pins_are_located_errors(make_config):
    problems = expect_problems(make_config, """
        version: 1
        tags:
          a: {type: float32, modbus: {address: 100}}
          b: {type: int16, modbus: {address: 101}}
    """)
    assert len(problems) == 1
    location, message = problems[0].split(": ", 1)
    assert location.endswith("tagdb.yaml:5:38"), problems[0]  # b's address value
    assert "'b' (holding registers 101) overlaps 'a' (holding registers 100..101, pinned" in message


def test_a_pin_on_an_auto_allocated_tag_is_an_error_not_a_move(make_config):
    problems = expect_problems(make_config, """
        version: 1
        tags:
          a: {type: float64}
          b: {type: int16, modbus: {address: 2}}
    """)
    assert len(problems) == 1 and ":5:38:" in problems[0]
    assert "overlaps 'a' (holding registers 0..3, auto-allocated" in problems[0]


@pytest.mark.parametrize(
    ("spec", "where", "words"),
    [
        ("{type: float32, modbus: {table: coil}}", ":4:38:", "coils hold single bits"),
        ("{type: string, modbus: {scale: 10}}", ":4:37:", "'scale' does not apply to a string"),
        ("{type: int16, modbus: {words: 4}}", ":4:36:", "'words' is only for string tags"),
        ("{type: float32, modbus: {register_type: float32, scale: 10}}", ":4:62:", "'scale' needs an integer register_type"),
        ("{type: bool, modbus: {scale: 10}}", ":4:35:", "'scale' does not apply to coils"),
        ("{type: float64, modbus: {address: 65534}}", ":4:40:", "beyond the last address 65535"),
    ],
)
def test_options_that_cannot_work_are_located_errors(make_config, spec, where, words):
    problems = expect_problems(make_config, f"""
        version: 1
        tags:
          x: {spec}
    """)
    assert len(problems) == 1 and where in problems[0] and words in problems[0], problems


def test_an_address_in_a_multi_instance_template_is_an_error(make_config):
    problems = expect_problems(make_config, """
        version: 1
        templates:
          robot:
            instances: [r01, r02]
            tags:
              goal: {type: uint16, modbus: {address: 10}}
    """)
    assert len(problems) == 1 and ":7:46:" in problems[0] and "shared by all 2 instances" in problems[0]


def test_auto_allocation_may_not_run_into_the_system_block(make_config):
    problems = expect_problems(make_config, """
        version: 1
        tags:
          a: {type: float64}
          b: {type: float64}
        servers:
          modbus: {system_base: 6}
    """)
    assert len(problems) == 1 and ":5:3:" in problems[0] and "into the _sys. tag block at 6" in problems[0]


def test_schema_rejects_unknown_modbus_options(make_config):
    with pytest.raises(ConfigError) as caught:
        make_config("version: 1\ntags:\n  a: {type: int16, modbus: {adress: 3}}\n")
    assert "did you mean 'address'" in str(caught.value)


# -- codec -------------------------------------------------------------------------------------


@pytest.mark.parametrize("order", ["big", "little"])
@pytest.mark.parametrize(
    ("data_type", "fmt", "value"),
    [
        (DataType.INT16, "h", -12345),
        (DataType.UINT16, "H", 54321),
        (DataType.INT32, "i", -123456789),
        (DataType.UINT32, "I", 4023456789),
        (DataType.FLOAT32, "f", -1.25),
        (DataType.FLOAT64, "d", 6.02214076e23),
    ],
)
def test_codec_matches_struct_in_both_word_orders(data_type, fmt, value, order):
    codec = RegisterCodec(data_type, data_type, struct.calcsize(fmt) // 2, None, order)
    data = struct.pack(">" + fmt, value)
    expected = [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
    if order == "little":
        expected.reverse()
    assert codec.encode(value) == expected
    assert codec.decode(expected) == value


def test_codec_scaling_saturation_and_strings():
    scaled = RegisterCodec(DataType.FLOAT32, DataType.INT16, 1, 100.0)
    assert scaled.encode(12.345) == [1234] or scaled.encode(12.345) == [1235]
    assert scaled.encode(1000.0) == [32767]  # saturates at int16
    assert scaled.encode(-1000.0) == [struct.unpack(">H", struct.pack(">h", -32768))[0]]
    assert scaled.encode(math.nan) == [0]
    assert scaled.decode([1234]) == pytest.approx(12.34)
    integer = RegisterCodec(DataType.UINT16, DataType.UINT16, 1, 0.1)
    assert integer.decode([3]) == 30 and isinstance(integer.decode([3]), int)
    text = RegisterCodec(DataType.STRING, None, 2)
    assert text.encode("héllo") == [int.from_bytes(b"h\xc3", "big"), int.from_bytes(b"\xa9l", "big")]
    assert text.encode("aé") == [int.from_bytes(b"a\xc3", "big"), int.from_bytes(b"\xa9\0", "big")]
    assert text.encode("abcé") == [int.from_bytes(b"ab", "big"), int.from_bytes(b"c\0", "big")]  # no half character
    assert text.decode([int.from_bytes(b"ok", "big"), 0]) == "ok"
    with pytest.raises(CodecError):
        text.decode([0xC328, 0])


# -- softplc modbus-map ------------------------------------------------------------------------


def test_modbus_map_cli_formats(make_config, capsys):
    config = str(make_config(BASE + "  xgoal: {type: float64, unit: m}\n  pos: {type: float64, access: ro}\n"
                             "servers:\n  modbus: {unit_id: 7}\ntasks:\n  fast: {interval: 10ms}\n").path)
    assert main(["modbus-map", config]) == 0
    table = capsys.readouterr().out
    assert "unit 7" in table and "xgoal" in table and "40021" in table and "_sys.fast.cycles" in table
    assert main(["modbus-map", config, "--format", "csv", "--table", "holding"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    xgoal = next(row for row in rows if row["tag"] == "xgoal")
    assert xgoal == {**xgoal, "table": "holding", "address": "20", "number": "21", "reference": "40021", "type": "float64", "words": "4", "access": "rw", "unit": "m"}
    assert {row["table"] for row in rows} == {"holding"}
    assert main(["modbus-map", config, "--format", "json", "--no-system"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["unit_id"] == 7 and document["port"] == 5020
    assert not [row for row in document["tags"] if row["tag"].startswith("_sys.")]
    assert {row["table"] for row in document["tags"]} == {"coil", "discrete_input", "holding", "input"}
    assert len(document["tags"]) == 6 + 5 + 2  # template instances, plain tags, the two added here


def test_modbus_map_cli_reports_config_errors_with_location(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text("version: 1\ntags:\n  a: {type: int16, modbus: {address: 5}}\n  b: {type: int16, modbus: {address: 5}}\n")
    assert main(["modbus-map", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:4:38: 'b' (holding registers 5) overlaps 'a'" in err


def test_an_overlap_hidden_behind_a_short_tag_is_found(make_config):
    problems = expect_problems(make_config, """
        version: 1
        tags:
          wide:  {type: float64, modbus: {address: 100}}
          small: {type: int16, modbus: {address: 101}}
          other: {type: int16, modbus: {address: 102}}
    """)
    assert len(problems) == 2
    assert "'small' (holding registers 101) overlaps 'wide'" in problems[0]
    assert "'other' (holding registers 102) overlaps 'wide'" in problems[1]


def test_run_flags_build_or_skip_the_modbus_adapter(make_config, capsys):
    from softplc.app.adapters import build_adapters
    from softplc.app.cli import build_parser

    config = make_config(BASE + "servers:\n  modbus: {port: 1502}\n")
    parser = build_parser()
    modbus = [a for a in build_adapters(config, parser.parse_args(["run", "--no-opcua"])) if a.name == "modbus"]
    assert len(modbus) == 1 and modbus[0].settings.port == 1502
    moved = [a for a in build_adapters(config, parser.parse_args(["run", "--no-opcua", "--modbus-port", "0", "--modbus-host", "0.0.0.0"])) if a.name == "modbus"]
    assert (moved[0].settings.host, moved[0].settings.port) == ("0.0.0.0", 0)
    assert not [a for a in build_adapters(config, parser.parse_args(["run", "--no-opcua", "--no-modbus"])) if a.name == "modbus"]
    # no servers: section: served on loopback and the default port, like OPC UA (issue 14, item 19)
    default = [a for a in build_adapters(make_config(BASE), parser.parse_args(["run", "--no-opcua"])) if a.name == "modbus"]
    assert (default[0].settings.host, default[0].settings.port) == ("127.0.0.1", 5020)
    with pytest.raises(SystemExit):
        parser.parse_args(["run", "--modbus-port", "70000"])
    assert "port 70000 is outside 0..65535" in capsys.readouterr().err


def test_system_tags_that_do_not_fit_are_left_out_with_a_warning(make_config, caplog):
    config = make_config(BASE + "tasks:\n  fast: {interval: 10ms}\nservers:\n  modbus: {system_base: 65500}\n")
    with caplog.at_level("WARNING", logger="softplc.adapters.modbus.address_map"):
        m = build_address_map(config)
    assert "r01_busy" in m.by_tag and "_sys.reset_stats" in m.by_tag  # coils still fit
    assert "_sys.fast.latency_ms_p99" not in m.by_tag
    assert all(mapping.end <= 65536 for mapping in m.mappings)
    assert "_sys. tags (from _sys." in caplog.text and "not served over Modbus" in caplog.text


def test_a_template_too_big_for_modbus_is_one_message_not_one_per_instance(make_config) -> None:
    from softplc.config.yamlsource import ConfigError

    with pytest.raises(ConfigError) as raised:
        make_config("""\
            version: 1
            templates:
              blob:
                count: 5000
                prefix: b
                tags:
                  text: {type: string}
            """)
    [problem] = raised.value.problems
    assert "'b4097_text' and 903 more tags after it do not fit the holding registers when packed automatically" in problem.message
    assert "modbus: {enabled: false}" in problem.message and (problem.location.line, problem.location.column) == (7, 7)
