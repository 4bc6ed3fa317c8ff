"""Good configurations: templates, per-instance initials, bindings, for_each, durations, schema."""

from __future__ import annotations

import json

import jsonschema
import pytest
import yaml
from conftest import REPO

from softplc.config import PlantConfig, load_config
from softplc.config.sections import config_schema
from softplc.core.datatypes import DataType
from softplc.core.tags import Access

PROGRAMS = REPO / "tests" / "configs" / "sample_programs.py"


def test_template_count_and_prefix_expand_with_padded_numbers(make_config) -> None:
    config = make_config(
        """
        version: 1
        templates:
          robot:
            count: 3
            tags:
              xpos: {type: float64, unit: m}
              busy: {type: bool}
          station:
            prefix: st
            count: 120
            group: Plant/Stations
            tags:
              level: {type: float32}
        """
    )
    names = [tag.name for tag in config.tags]
    assert names[:6] == ["r01_xpos", "r01_busy", "r02_xpos", "r02_busy", "r03_xpos", "r03_busy"]
    assert config.instances["robot"] == ["r01", "r02", "r03"]
    # more than 99 instances: three digits, so names sort naturally
    assert config.instances["station"][0] == "st001" and config.instances["station"][-1] == "st120"
    assert len(config.tags) == 3 * 2 + 120
    assert config.tag("r02_xpos").group == "Robots/r02"
    assert config.tag("st007_level").group == "Plant/Stations/st007"
    assert config.tag("r01_xpos").unit == "m"


def test_per_instance_initials_override_the_template(make_config) -> None:
    config = make_config(
        """
        version: 1
        templates:
          robot:
            instances: [r01, r02, r03]
            tags:
              xpos: {type: float64, initial: 1.0}
              load: {type: uint16, initial: 5, max: 20}
            initial:
              r02: {xpos: 7.925, load: 20}
        """
    )
    assert [config.tag(f"{r}_xpos").initial for r in ("r01", "r02", "r03")] == [1.0, 7.925, 1.0]
    assert [config.tag(f"{r}_load").initial for r in ("r01", "r02", "r03")] == [5, 20, 5]


def test_tag_attributes_and_defaults(make_config) -> None:
    config = make_config(
        """
        version: 1
        tags:
          level: {type: float32, initial: 0.1, unit: "%", min: 0, max: 100, access: ro, retain: true,
                  group: Plant/Tank, description: tank level, modbus: {table: input, address: 7}}
          count: {type: int32}
          name: {type: string}
          flag: {type: bool, initial: 1}
          big: {type: float64, initial: 3}
        """
    )
    level = config.tag("level")
    assert level.type is DataType.FLOAT32
    assert level.initial == pytest.approx(0.1) and level.initial != 0.1  # rounded to single precision
    assert (level.unit, level.min, level.max, level.access, level.retain) == ("%", 0, 100, Access.RO, True)
    assert (level.group, level.description) == ("Plant/Tank", "tank level")
    assert level.options == {"modbus": {"table": "input", "address": 7}}
    count = config.tag("count")
    assert (count.initial, count.access, count.retain, count.min, count.max, count.group) == (0, Access.RW, False, None, None, "")
    assert config.tag("name").initial == ""
    assert config.tag("flag").initial is True
    big = config.tag("big")
    assert big.initial == 3.0 and isinstance(big.initial, float)


def test_durations_priorities_and_watchdog_default(make_config) -> None:
    config = make_config(
        """
        version: 1
        tasks:
          a: {interval: 10ms, priority: 0}
          b: {interval: 1.5s, watchdog: 200ms}
          c: {interval: 2min}
          d: {interval: 250us}
          e: {interval: 5}
        """
    )
    tasks = {task.name: task for task in config.tasks}
    assert tasks["a"].interval == pytest.approx(0.01) and tasks["a"].priority == 0
    assert tasks["a"].watchdog == tasks["a"].interval  # the watchdog defaults to the interval
    assert tasks["b"].interval == 1.5 and tasks["b"].watchdog == pytest.approx(0.2)
    assert tasks["b"].priority == 10  # the default priority
    assert tasks["c"].interval == 120.0
    assert tasks["d"].interval == pytest.approx(250e-6)
    assert tasks["e"].interval == 5.0


def _summer_config(make_config) -> PlantConfig:
    return make_config(
        f"""
        version: 1
        templates:
          line:
            instances: [l1, l2]
            tags:
              a: {{type: float64, initial: 1}}
              b: {{type: float64, initial: 2}}
              total: {{type: float64}}
              scans: {{type: uint32}}
              scaled: {{type: float64}}
        tasks:
          fast:
            interval: 10ms
            programs:
              - name: sum_{{line}}
                program: {PROGRAMS}:Summer
                for_each: line
                bind: {{parts: ["{{line}}_a", "{{line}}_b"], total: "{{line}}_total", scans: "{{line}}_scans"}}
              - name: mix
                program: {PROGRAMS}:Mixer
                bind: {{source: l1_total, target: l1_scaled}}
                params: {{recipe: "{{line}}-soup", gain: 2, hold: 250ms}}
                restart: {{delay: 2s, max: 5}}
                enabled: false
        """
    )


def test_for_each_list_bindings_and_params(make_config) -> None:
    config = _summer_config(make_config)
    programs = config.tasks[0].programs
    assert [program.name for program in programs] == ["sum_l1", "sum_l2", "mix"]
    assert programs[1].bindings == {"parts": ["l2_a", "l2_b"], "total": "l2_total", "scans": "l2_scans"}
    mix = programs[2]
    # the placeholder is not substituted outside for_each; gain 2 becomes the float the default is
    assert mix.params == {"recipe": "{line}-soup", "gain": 2.0, "hold": 0.25}
    assert isinstance(mix.params["gain"], float)
    assert (mix.restart.automatic, mix.restart.delay, mix.restart.max_restarts, mix.enabled) == (True, 2.0, 5, False)
    assert config.program_count == 3


async def test_list_bindings_run(make_config, tmp_path) -> None:
    from softplc.app.runtime import Runtime
    from softplc.core.clock import SimClock

    runtime = Runtime(_summer_config(make_config), SimClock(), state_dir=tmp_path)
    await runtime.run(duration=0.1)
    db = runtime.db
    assert db.value("l1_total") == 3.0 and db.value("l2_total") == 3.0
    assert db.value("l1_scans") == 10  # cycles at 0, 10, ..., 90 ms
    assert db.value("l1_scaled") == 0.0  # the disabled program never ran
    assert runtime.program("mix").state.value == "STOPPED"


def test_default_plant() -> None:
    config = load_config(REPO / "tagdb.yaml")
    assert config.instances["robot"] == ["r01", "r02", "r03"]
    assert config.instances["task"] == ["t01", "t02"]
    names = {tag.name for tag in config.tags}
    for robot in ("r01", "r02", "r03"):
        assert {f"{robot}_{t}" for t in ("xpos", "ypos", "status", "tcurr", "currloc", "xgoal", "ygoal", "loadcap", "load", "loadstat")} <= names
    for task in ("t01", "t02"):
        assert {f"{task}_{t}" for t in ("iBM", "iBL", "iFr", "iBC", "qSM", "qSL", "qFr", "qSC", "sCDr", "sPPi", "sPD", "src_x", "dest_y")} <= names
    # thesis initial plant (SPEC section 2)
    assert config.tag("t01_iFr").initial == 30 and config.tag("t01_iBC").initial == 100
    assert config.tag("t02_sCDr").initial == 5 and config.tag("t01_sPPi").initial == pytest.approx(0.5)
    assert (config.tag("t02_src_x").initial, config.tag("t02_dest_y").initial) == (18.5, 2.4)
    assert config.tag("r01_loadcap").initial == 20
    assert (config.tag("r03_xpos").initial, config.tag("r03_ypos").initial) == (7.925, 4.525)
    assert config.tasks and config.program_count >= 1


def test_schema_is_a_valid_json_schema_and_the_default_plant_validates() -> None:
    CONFIG_SCHEMA = config_schema()
    jsonschema.Draft202012Validator.check_schema(CONFIG_SCHEMA)
    data = yaml.safe_load((REPO / "tagdb.yaml").read_text())
    errors = list(jsonschema.Draft202012Validator(CONFIG_SCHEMA).iter_errors(data))
    assert errors == []
    # and it really constrains: a misspelt key fails the schema alone (no Python checks)
    data["tsks"] = data.pop("tasks")
    assert list(jsonschema.Draft202012Validator(CONFIG_SCHEMA).iter_errors(data))
    assert json.loads(json.dumps(CONFIG_SCHEMA)) == CONFIG_SCHEMA  # serialisable as printed


def test_shared_outputs_and_disabled_programs_are_not_double_writes(make_config) -> None:
    config = make_config(
        f"""
        version: 1
        templates:
          line:
            instances: [l1, l2]
            tags:
              count: {{type: uint32, shared_output: true}}   # a counter both programs increment
        tags:
          a: {{type: float64}}
          handshake: {{type: float64, shared_output: true}}  # one sets it, the other clears it
          spare: {{type: float64}}
        tasks:
          fast:
            interval: 10ms
            programs:
              - {{name: set, program: "{PROGRAMS}:Mixer", params: {{recipe: x}}, bind: {{source: a, target: handshake}}}}
              - {{name: count_a, program: "{PROGRAMS}:Summer", bind: {{parts: [a], total: spare, scans: l1_count}}}}
          slow:
            interval: 1s
            programs:
              - {{name: clear, program: "{PROGRAMS}:Mixer", params: {{recipe: y}}, bind: {{source: a, target: handshake}}}}
              - {{name: count_b, program: "{PROGRAMS}:Summer", bind: {{parts: [a], total: a, scans: l1_count}}}}
              - {{name: old, program: "{PROGRAMS}:Mixer", params: {{recipe: z}}, enabled: false, bind: {{source: a, target: spare}}}}
        """
    )
    assert config.program_count == 5


def test_every_shipped_plant_and_scenario_writes_each_output_from_one_program_or_says_it_is_shared() -> None:
    from softplc.latency.plant import SCENARIO_NAMES, handshake_config
    from softplc.scenarios.plant import build_plant
    from softplc.scenarios.spec import builtin_scenarios, load_scenario

    load_config(REPO / "tagdb.yaml")
    for scenario in SCENARIO_NAMES:
        handshake_config(scenario, 0.01)
    paths = builtin_scenarios()
    assert len(paths) >= 12
    for path in paths:
        scenario = load_scenario(path)
        build_plant(scenario, [[1] * len(scenario.tasks) for _ in scenario.robots])


def test_a_ctrl_c_while_a_program_module_is_imported_stays_a_ctrl_c(make_config, tmp_path) -> None:
    # Python 3.11 wraps an exception raised in a descriptor's __set_name__ (softplc's InOut) in
    # "RuntimeError: Error calling __set_name__": a Ctrl-C at that moment read as a broken program
    # (exit status 2, "cannot load program") in a suite run of the Ctrl-C-at-start-up test.
    (tmp_path / "interrupted.py").write_text(
        "from softplc.core.program import Program\n\n\n"
        "class Named:\n"
        "    def __set_name__(self, owner, name):\n"
        "        raise KeyboardInterrupt\n\n\n"
        "class Interrupted(Program):\n"
        "    field = Named()\n")
    with pytest.raises(KeyboardInterrupt):
        make_config("""
            version: 1
            tasks:
              fast:
                interval: 10ms
                programs:
                  - {name: p, program: "interrupted.py:Interrupted"}
        """)
