"""The historian inside a runtime on the simulated clock: what is recorded, how, and where."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import pytest
from conftest import REPO

from softplc.adapters.history.queries import HistoryReader
from softplc.adapters.history.settings import SIM_FILE
from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from softplc.core.tags import Quality
from softplc.storage import Database, StorageSettings

SUPPORT = REPO / "tests" / "history_support.py"
EPOCH = 1_767_225_600.0  # SimClock's wall time at 0

PLANT = f"""
version: 1
plant: {{name: waves}}
tags:
  wave:  {{type: float64, min: -1, max: 1, unit: m}}
  steps: {{type: int32}}
  state: {{type: string}}
  spare: {{type: float64}}
tasks:
  main:
    interval: 100ms
    programs:
      - {{name: wave, program: "{SUPPORT}:Wave", bind: {{wave: wave, steps: steps, state: state}}, params: {{period: 10.0}}}}
servers: {{opcua: {{enabled: false}}, modbus: {{enabled: false}}}}  # no server on a fixed port
history:
  flush_period: 100ms
  record:
    - {{tags: [wave, steps, state, spare], deadband: 0}}
    - {{tags: "wave", compression: {{deviation: 2%, max_interval: 5s}}}}
    - {{tags: "spare", record: false}}
"""


async def run_plant(path: Path, state: Path, seconds: float) -> Runtime:
    config = load_config(path)
    runtime = Runtime(config, SimClock(), state_dir=state)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    try:
        await runtime.clock.sleep_until(seconds)
    finally:
        await runtime.stop()
    return runtime


def sim_reader(state: Path) -> HistoryReader:
    return HistoryReader(Database(StorageSettings.sqlite(state / SIM_FILE)), "waves")


async def test_a_simulated_run_records_on_the_simulated_clock_with_compression(tmp_path: Path) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(PLANT))
    state = tmp_path / "state"
    runtime = await run_plant(path, state, 60.05)
    recorder = next(a for a in runtime.adapters if a.name == "history")
    assert "recording 3 tags" in recorder.describe() and "simulated time" in recorder.describe()
    assert not (state / "history.sqlite").exists()  # never mixed with the plant's own history
    reader = sim_reader(state)
    assert set(reader.historized()) == {"wave", "steps", "state"}
    wave = reader.raw("wave", EPOCH, EPOCH + 61).samples
    # 600 scans; compression keeps the sine within 2 * 2% of its range (0.08) with far fewer samples.
    assert 10 < len(wave) < 150
    assert wave[0].time == EPOCH  # timestamps are simulated wall time
    for when in (3.05, 17.35, 42.45):
        (value,) = reader.at_time("wave", [EPOCH + when])
        assert abs(value.value - math.sin(round(when, 1) / 10.0)) <= 0.08 + 0.02, when  # +1 scan of movement
    # max_interval 5 s: no two stored values of the wave more than 5 s apart.
    assert max(b.time - a.time for a, b in zip(wave, wave[1:])) <= 5.0 + 1e-6
    steps = reader.raw("steps", EPOCH, EPOCH + 61).samples
    assert [s.value for s in steps[:-1]] == list(range(0, 61))  # every change of an integer, no compression
    # The end of the recording: a BAD sample without a value (no data until a next run).
    assert steps[-1].quality is Quality.BAD and math.isnan(steps[-1].value) and steps[-1].time >= steps[-2].time
    states = [s.value for s in reader.raw("state", EPOCH, EPOCH + 61).samples]
    assert states[:4] == ["", "low", "high", "low"]  # the initial value, then sin(0) = 0 is "low", alternating every 31.4 s
    reader.close()


async def test_a_second_simulated_run_replaces_the_first_ones_history(tmp_path: Path) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(PLANT))
    state = tmp_path / "state"
    await run_plant(path, state, 10.0)
    await run_plant(path, state, 5.05)
    reader = sim_reader(state)
    assert [s.value for s in reader.raw("steps", EPOCH, EPOCH + 100).samples if s.quality is Quality.GOOD] == [0, 1, 2, 3, 4, 5]
    reader.close()


async def test_quality_changes_are_recorded(tmp_path: Path) -> None:
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(PLANT).replace('{tags: "spare", record: false}', '{tags: "spare", deadband: 0.5}'))
    config = load_config(path)
    runtime = Runtime(config, SimClock(), state_dir=tmp_path / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    try:
        clock, db = runtime.clock, runtime.db
        await clock.sleep_until(1.0)
        db.submit([("spare", 0.2)], "test")  # inside the deadband: not recorded
        await clock.sleep_until(2.0)
        db.submit_quality(["spare"], Quality.BAD, "driver")  # a quality change always is
        await clock.sleep_until(3.0)
        db.submit([("spare", 0.3)], "test")  # good again
        await clock.sleep_until(4.0)
    finally:
        await runtime.stop()
    reader = sim_reader(tmp_path / "state")
    rows = [(round(s.time - EPOCH, 1), s.value, s.quality) for s in reader.raw("spare", EPOCH, EPOCH + 10).samples]
    assert rows[:-1] == [(0.0, 0.0, Quality.GOOD), (2.0, 0.2, Quality.BAD), (3.0, 0.3, Quality.GOOD)]
    assert rows[-1][0] == 4.0 and math.isnan(rows[-1][1]) and rows[-1][2] is Quality.BAD  # the end of the recording
    reader.close()


def test_problems_in_the_history_section_are_located(make_config) -> None:
    from softplc.config.yamlsource import ConfigError

    with pytest.raises(ConfigError) as raised:  # softplc check and run: the section's owner reports them
        make_config(textwrap.dedent("""\
        version: 1
        tags:
          level: {type: float64}
          count: {type: int32, min: 0, max: 10}
        history:
          backend: postgresql
          retention: 30 days
          partition: 90min
          record:
            - {tags: ["lev*", "r*_xpos"], deadband: 1%}
            - {tags: count, deadband: -3, compression: {deviation: 1, max_interval: soon}}
        """))
    messages = [f"{p.location.line}:{p.location.column}: {p.message}" for p in raised.value.problems]
    assert sorted(messages) == sorted([
        "6:12: backend postgresql needs a dsn, e.g. dsn: 'host=127.0.0.1 port=5432 dbname=plant'",
        "7:14: bad retention '30 days': not a duration: '30 days' (write e.g. 10ms, 1s, 2min)",
        "8:14: partition must be a whole number of hours (e.g. 24h, 1d, 1w), not 90min",
        "10:45: deadband 1% is a percentage of the tag's range, but level has no min and max; give an absolute amount",
        "10:23: tag pattern 'r*_xpos' matches no tag",
        "11:31: bad deadband -3: must be zero or more, not -3",
        "11:77: bad max_interval 'soon': not a duration: 'soon' (write e.g. 10ms, 1s, 2min)",
    ])


def test_a_partition_of_zero_is_refused_like_the_audit_trails(make_config) -> None:
    from softplc.config.yamlsource import ConfigError

    with pytest.raises(ConfigError) as raised:  # a store cut into partitions of 0 s could hold no row
        make_config("version: 1\ntags:\n  level: {type: float64}\nhistory:\n  partition: 0\n  record: [{tags: level}]\n")
    assert [p.message for p in raised.value.problems] == ["partition must be a whole number of hours (e.g. 24h, 1d, 1w), not 0"]


def test_rules_merge_in_order_and_a_tags_own_rule_comes_last(make_config) -> None:
    from softplc.adapters.history.settings import HistorySettings, tag_rule

    config = make_config("""\
        version: 1
        tags:
          r01_xpos: {type: float64, min: 0, max: 20}
          r02_xpos: {type: float64, min: 0, max: 20}
          r01_mode: {type: string}
        history:
          record:
            - {tags: "r*", deadband: 5%}
            - {tags: "r02_*", compression: {deviation: 0.1, min_interval: 1s}}
        """)
    own = tag_rule("r01_xpos", {"deadband": 0.25})
    settings = HistorySettings.from_config(config, [own, tag_rule("r01_mode", False)])
    policies = settings.policies(config.tags)
    assert set(policies) == {"r01_xpos", "r02_xpos"}  # r01_mode's own key says record: false
    assert policies["r01_xpos"].deadband == 0.25 and policies["r01_xpos"].compression is None
    assert policies["r02_xpos"].deadband == pytest.approx(1.0)  # 5% of 0..20
    assert policies["r02_xpos"].compression == (0.1, 1.0, 3600.0)


def test_the_default_plant_records_its_robot_and_task_tags() -> None:
    from softplc.adapters.history.settings import HistorySettings, problems

    config = load_config(REPO / "tagdb.yaml")
    assert problems(config) == []
    policies = HistorySettings.from_config(config).policies(config.tags)
    for name in ("r01_xpos", "r03_ypos", "r02_status", "r01_navstate", "t01_iBL", "t02_qSL", "t01_Tw"):
        assert name in policies, name
    assert policies["r01_xpos"].compression is not None and "r01_route" not in policies


@pytest.mark.parametrize("simulated", [True, False])
async def test_a_store_that_cannot_be_opened_stops_the_start_with_the_reason(tmp_path: Path, simulated: bool) -> None:
    from softplc.app.runtime import AdapterError
    from softplc.core.clock import RealClock

    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(PLANT))
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("a file where the state directory should be")
    config = load_config(path)
    runtime = Runtime(config, SimClock() if simulated else RealClock(), state_dir=blocker)
    for adapter in build_adapters(config, None):
        if adapter.name == "history":  # the audit trail's store is in the same directory and would fail first
            runtime.add_adapter(adapter)
    name = "history-sim.sqlite" if simulated else "history.sqlite"
    with pytest.raises(AdapterError, match=rf"history: cannot open SQLite .*not-a-directory/{name}"):
        await runtime.start()


def test_a_tags_own_history_key_and_its_templates_are_rules(make_config) -> None:
    from softplc.adapters.history.section import tag_rules
    from softplc.adapters.history.settings import HistorySettings
    from softplc.config.yamlsource import ConfigError

    config = make_config("""\
        version: 1
        templates:
          robot:
            instances: [r01, r02]
            history: {deadband: 0.05}
            tags:
              xpos: {type: float64, min: 0, max: 20}
              mode: {type: string, history: false}
        tags:
          level: {type: float32, min: 0, max: 100, history: {deadband: 1%}}
          note: {type: string, history: true}
          other: {type: float64}
        """)
    policies = HistorySettings.from_config(config, tag_rules(config)).policies(config.tags)
    assert set(policies) == {"r01_xpos", "r02_xpos", "level", "note"}
    assert policies["r01_xpos"].deadband == 0.05 and policies["level"].deadband == pytest.approx(1.0)
    with pytest.raises(ConfigError) as raised:
        make_config("version: 1\ntags:\n  free: {type: float64, history: {deadband: 2%}}\n")
    [problem] = raised.value.problems
    assert (problem.location.line, problem.location.column) == (3, 45)
    assert "percentage of the tag's range, but 'free' has no min and max" in problem.message
