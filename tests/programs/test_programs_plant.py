"""The plant simulator (matHand_sim) and the supply-chain demand, run in a runtime on the simulated clock."""

from __future__ import annotations

import pytest

from programs.plant_simulator import MaterialHandlingPlant
from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock
from softplc.core.program import ProgramContext

PLANT = """
version: 1
templates:
  task:
    instances: [t01, t02]
    tags:
      iBM: {type: uint16}
      iBL: {type: float32}
      iFr: {type: float32, initial: 30}
      iBC: {type: uint16, initial: 100}
      qSM: {type: uint16}
      qSL: {type: float32, max: 100}
      qFr: {type: float32}
      qSC: {type: uint16, initial: 100}
      sPD: {type: float32}
    initial:
      t02: {iFr: 10}
  robot:
    instances: [r01]
    tags:
      tcurr: {type: uint16}
      currloc: {type: uint16}
      loadcap: {type: uint16, initial: 20}
      load: {type: uint16}
      loadstat: {type: bool}
tasks:
  plant:
    interval: 100ms
    programs:
      - name: plant
        program: programs.plant_simulator:MaterialHandlingPlant
        bind:
          iBM: [t01_iBM, t02_iBM]
          iBC: [t01_iBC, t02_iBC]
          iFr: [t01_iFr, t02_iFr]
          iBL: [t01_iBL, t02_iBL]
          qSM: [t01_qSM, t02_qSM]
          qSC: [t01_qSC, t02_qSC]
          qSL: [t01_qSL, t02_qSL]
          qFr: [t01_qFr, t02_qFr]
          tcurr: [r01_tcurr]
          currloc: [r01_currloc]
          loadcap: [r01_loadcap]
          load: [r01_load]
          loadstat: [r01_loadstat]
      - name: demand
        program: programs.supply_chain:DemandGenerator
        bind: {sPD: [t01_sPD, t02_sPD]}
        params: {low: [0, 50], high: [50, 100], period: 10s, seed: 7}
"""


async def test_input_buffers_fill_one_item_every_60_over_iFr_seconds(make_config, tmp_path):
    runtime = Runtime(make_config(PLANT), SimClock(), state_dir=tmp_path)
    await runtime.run(duration=60.05)
    value = runtime.db.value
    assert value("t01_iBM") == 30  # 30 items/min: one every 2 s
    assert value("t02_iBM") == 10  # 10 items/min: one every 6 s
    assert value("t01_iBL") == pytest.approx(30.0)
    assert runtime.program("plant").state.value == "RUNNING"


async def test_input_buffer_stops_at_its_capacity(make_config, tmp_path):
    config = make_config(PLANT.replace("      t02: {iFr: 10}", "      t02: {iFr: 10}\n      t01: {iBC: 5, iFr: 600}"))
    runtime = Runtime(config, SimClock(), state_dir=tmp_path)
    await runtime.run(duration=30)
    assert runtime.db.value("t01_iBM") == 5
    assert runtime.db.value("t01_iBL") == pytest.approx(100.0)


async def test_demand_is_drawn_in_each_tasks_range_and_repeats(make_config, tmp_path):
    seen: list[tuple[float, float]] = []
    for run in range(2):
        runtime = Runtime(make_config(PLANT), SimClock(), state_dir=tmp_path / str(run))
        values: list[tuple[float, float]] = []
        runtime.engine.after_cycle(lambda task, db=runtime.db, values=values: values.append((db.value("t01_sPD"), db.value("t02_sPD"))))
        await runtime.run(duration=100)
        distinct = sorted(set(values[1:]))
        assert all(0 <= low <= 50 and 50 <= high <= 100 for low, high in distinct)
        assert len(distinct) >= 5  # a new draw every 10 s
        if run == 0:
            seen = values
    assert values == seen  # same seed, same demand


def plant_program() -> MaterialHandlingPlant:
    program = MaterialHandlingPlant(ProgramContext("plant", SimClock(), {}))
    program.setup()
    program.iBM, program.iBC, program.iFr, program.iBL = [50, 5], [100, 100], [0.0, 0.0], [0.0, 0.0]
    program.qSM, program.qSC, program.qSL, program.qFr = [0, 95], [100, 100], [0.0, 0.0], [0.0, 0.0]
    program.tcurr, program.currloc, program.loadcap, program.load, program.loadstat = [1, 2], [0, 0], [20, 20], [0, 0], [False, False]
    return program


def test_a_robot_at_the_source_is_loaded_once_per_visit():
    program = plant_program()
    program.currloc = [2, 2]
    program.scan()
    assert program.load == [20, 5]  # min(iBM, loadcap)
    assert program.iBM == [30, 0]
    assert program.loadstat == [True, True]
    assert program.iBL == [30.0, 0.0]
    program.scan()  # still standing there with loadstat set: no second load
    assert program.load == [20, 5] and program.iBM == [30, 0]


def test_a_robot_at_the_destination_is_unloaded_without_overfilling():
    program = plant_program()
    program.currloc, program.load = [4, 4], [20, 20]
    program.scan()
    assert program.qSM == [20, 100]
    assert program.load == [0, 15]  # task 2's storage had room for 5: the rest stays on the robot
    assert program.loadstat == [True, True]
    assert program.qSL == [20.0, 100.0]


def test_a_robot_elsewhere_or_on_no_task_is_left_alone():
    program = plant_program()
    program.currloc, program.tcurr = [1, 4], [1, 0]
    program.scan()
    assert program.load == [0, 0] and program.loadstat == [False, False] and program.iBM == [50, 5]


async def test_output_fill_rate_is_the_level_per_minute_since_the_start(make_config, tmp_path):
    runtime = Runtime(make_config(PLANT.replace("      qSM: {type: uint16}", "      qSM: {type: uint16, initial: 30}")),
                      SimClock(), state_dir=tmp_path)
    await runtime.run(duration=120.05)
    # qFr = (60000 / sim_ms) * qSL = 60000 / 120000 * 30 = 15 (within one scan of 120 s)
    assert runtime.db.value("t01_qFr") == pytest.approx(15.0, rel=0.01)


async def test_handling_time_keeps_the_robot_at_the_station(make_config, tmp_path):
    text = (PLANT.replace("      loadstat: {type: bool}", "      loadstat: {type: bool}\n    initial:\n      r01: {tcurr: 1, currloc: 2}")
            .replace("      t02: {iFr: 10}", "      t02: {iFr: 10}\n      t01: {iBM: 50}")
            .replace("          loadstat: [r01_loadstat]", "          loadstat: [r01_loadstat]\n        params: {handling_time: 5s}"))
    runtime = Runtime(make_config(text), SimClock(), state_dir=tmp_path)
    seen: list[tuple[float, int, bool]] = []
    db = runtime.db
    runtime.engine.after_cycle(lambda task: seen.append((runtime.clock.now(), db.value("r01_load"), db.value("r01_loadstat"))))
    await runtime.run(duration=8)
    assert seen[0][1:] == (20, False)  # loaded on arrival ...
    ready = next(t for t, _, loadstat in seen if loadstat)
    assert ready == pytest.approx(5.0, abs=0.11)  # ... released after the handling time
    assert all(load == 20 for _, load, _ in seen)  # loaded once


async def test_lists_of_different_lengths_fault_the_program_with_a_clear_reason(make_config, tmp_path):
    text = PLANT.replace("          iBC: [t01_iBC, t02_iBC]", "          iBC: [t01_iBC]")
    runtime = Runtime(make_config(text), SimClock(), state_dir=tmp_path)
    await runtime.run(duration=1)
    instance = runtime.program("plant")
    assert instance.state.value == "FAULTED"
    assert "'iBC' is bound to 1 tag but 'iBM' to 2" in instance.error
    assert runtime.program("demand").state.value == "RUNNING"  # the rest of the plant keeps scanning
