"""The case-study scan programs: task weighting, dispatchers, motion sequencer (logic, scan by scan)."""

from __future__ import annotations

import math

import pytest

from programs.cooperative_dispatcher import CooperativeDispatcher
from programs.motion_sequencer import MotionSequencer
from programs.optimal_dispatcher import OptimalAssignment
from programs.task_weighting import TaskWeighting, lowest_weight, task_weight
from softplc.core.clock import SimClock
from softplc.core.program import Program, ProgramContext
from softplc.robotics.arrival import GOAL_TOLERANCE


def make(cls: type[Program], **params: object) -> Program:
    program = cls(ProgramContext("test", SimClock(), dict(params)))
    for name in cls.variables:
        setattr(program, name, None)  # as the runtime leaves a variable nobody bound
    program.setup()
    return program


# -- task weight (SPEC §3, thesis Figure 5.1) ----------------------------------------------------


def test_task_weight_is_the_thesis_formula():
    # x1 = 1/(30 * (50/100)) = 1/15, x2 = 1/0.5 = 2, x3 = (12 - 5) + (40 - 10) * 0.2 + 0.1 = 13.1
    assert task_weight(iFr=30, iBL=50, iBC=100, sPPi=0.5, qFr=12, qSL=40, sCDr=5, sPD=10) == pytest.approx(2 * 13.1 / 15)
    # a negative x3 gives a negative (more urgent) weight
    assert task_weight(iFr=10, iBL=20, iBC=100, sPPi=1.5, qFr=0, qSL=0, sCDr=5, sPD=0) == pytest.approx(
        (1 / (10 * 0.2)) * (1 / 1.5) * (-4.9))


@pytest.mark.parametrize("iFr, iBL, iBC", [(30, 0, 100), (0, 50, 100), (30, 50, 0), (0, 0, 0)])
def test_x1_is_zero_when_undefined(iFr, iBL, iBC):
    assert task_weight(iFr=iFr, iBL=iBL, iBC=iBC, sPPi=0.5, qFr=3, qSL=20, sCDr=0, sPD=0) == 0.0


def test_zero_profit_index_gives_zero_weight_not_an_error():
    assert task_weight(iFr=30, iBL=50, iBC=100, sPPi=0, qFr=3, qSL=20, sCDr=0, sPD=0) == 0.0


def test_lowest_weight_wins_and_ties_go_to_the_lower_task():
    assert lowest_weight([0.5, -2.0, 1.0]) == 2
    assert lowest_weight([1.0, 1.0]) == 1
    assert lowest_weight([3.0, 1.0, 1.0]) == 2
    assert lowest_weight([-1.0, -5.0], allowed=[1]) == 1
    assert lowest_weight([-1.0, -5.0], allowed=[]) == 0
    assert lowest_weight([-1.0, -5.0], allowed=[7]) == 0


def _weighting_inputs(program: Program, *, iBL: list[float], qSL: list[float], iFr: list[float] | None = None,
                      sPPi: list[float] | None = None, robots: int = 1) -> None:
    tasks = len(iBL)
    program.iFr = iFr or [30.0] * tasks
    program.iBL = iBL
    program.iBC = [100] * tasks
    program.sPPi = sPPi or [0.5] * tasks
    program.qFr = [0.0] * tasks
    program.qSL = qSL
    program.sCDr = [0.0] * tasks
    program.sPD = [0.0] * tasks
    program.Tw = [0.0] * tasks
    program.tnext = [0] * robots


def test_task_weighting_program_writes_weights_and_the_choice_for_every_robot():
    program = make(TaskWeighting)
    # equal outputs: the fuller input buffer has the smaller x1, so the lower weight
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0], robots=2)
    program.scan()
    assert program.Tw == [pytest.approx(task_weight(30, 20, 100, 0.5, 0, 10, 0, 0)), pytest.approx(task_weight(30, 60, 100, 0.5, 0, 10, 0, 0))]
    assert program.Tw[1] < program.Tw[0]
    assert program.tnext == [2, 2]


def test_higher_fill_rate_makes_a_task_more_urgent():
    program = make(TaskWeighting)
    _weighting_inputs(program, iBL=[50.0, 50.0], qSL=[10.0, 10.0], iFr=[30.0, 10.0])
    program.scan()
    assert program.tnext == [1]


def test_cooperative_dispatcher_keeps_dedicated_robots_and_moves_the_multi_skilled_one():
    program = make(CooperativeDispatcher, compatible=[[1], [2], [1, 2]])
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0], robots=3)
    program.scan()
    assert program.tnext == [1, 2, 2]  # task 2 is weighted lower: only r03 may follow it
    _weighting_inputs(program, iBL=[60.0, 20.0], qSL=[10.0, 10.0], robots=3)
    program.scan()
    assert program.tnext == [1, 2, 1]


def test_cooperative_dispatcher_gives_an_incompatible_robot_nothing():
    program = make(CooperativeDispatcher, compatible=[[], [1, 2]])
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0], robots=2)
    program.scan()
    assert program.tnext == [0, 2]


# -- motion sequencer (thesis robMotion) ---------------------------------------------------------

TASKS = {"src_x": [3.5, 18.5], "src_y": [7.5, 7.5], "dest_x": [1.8, 20.1], "dest_y": [2.5, 2.4]}


def sequencer(x: float = 7.9, y: float = 5.9) -> MotionSequencer:
    program = make(MotionSequencer)
    program.xpos, program.ypos, program.xgoal, program.ygoal = x, y, x, y
    program.status, program.currloc, program.prevloc, program.tcurr, program.loadstat = False, 0, 0, 0, False
    program.tnext = 0
    for name, values in TASKS.items():
        setattr(program, name, list(values))
    program.goals = [0, 0]
    return program


def arrive(program: MotionSequencer) -> None:
    """The robot drives to its goal and clears status (what the fleet's driver does)."""
    program.xpos, program.ypos, program.status = program.xgoal, program.ygoal, False


def test_sequencer_walks_a_full_trip():
    program = sequencer()
    program.scan()
    assert program.currloc == 0 and not program.status  # no task chosen yet: waits
    program.tnext = 2
    program.scan()
    assert (program.currloc, program.tcurr, program.status) == (1, 2, True)
    assert (program.xgoal, program.ygoal) == (18.5, 7.5)
    assert program.goals == [0, 1]
    program.scan()
    assert program.currloc == 1  # busy: nothing changes while travelling
    arrive(program)
    program.scan()
    assert program.currloc == 2 and program.prevloc == 1
    program.scan()
    assert program.currloc == 2  # waits for the plant to load it
    program.loadstat = True  # the plant loaded the robot
    program.scan()
    assert (program.currloc, program.status, program.loadstat) == (3, True, False)
    assert (program.xgoal, program.ygoal) == (20.1, 2.4)
    arrive(program)
    program.scan()
    assert program.currloc == 4
    program.loadstat = True  # the plant unloaded it
    program.scan()
    assert (program.currloc, program.loadstat, program.prevloc) == (0, False, 4)
    assert program.tcurr == 2  # the thesis keeps the last task in tcurr
    program.tnext = 1
    program.scan()
    assert (program.currloc, program.tcurr, program.goals) == (1, 1, [1, 1])


def test_sequencer_takes_the_robot_by_the_fleets_arrival_rule():
    # The driver clears status within GOAL_TOLERANCE; the sequencer must take the robot there too
    # (with the thesis's 0.3 m, a robot stopped 0.45 m out by another robot on the station stood still for good).
    assert GOAL_TOLERANCE == 0.5
    program = sequencer()
    program.tnext = 1
    program.scan()
    program.xpos, program.ypos = 3.5, 7.1  # 0.4 m short, still busy: travelling
    program.scan()
    assert program.currloc == 1
    program.status = False  # the robot cleared status 0.45 m out (a robot on the station kept it there)
    program.ypos = 7.05
    program.scan()
    assert program.currloc == 2


def test_sequencer_asks_again_when_the_robot_gave_up():
    program = sequencer()
    program.retry_after = 10.0
    program.tnext = 1
    program.scan()
    assert (program.currloc, program.status) == (1, True)
    program.status = False  # the driver gave up (navstate failed) 2 m short of the source
    program.xpos, program.ypos = 3.5, 5.5
    program.clock._now = 100.0  # noqa: SLF001 (the simulated clock is stepped by hand here)
    program.scan()
    program.clock._now = 109.0  # noqa: SLF001
    program.scan()
    assert (program.currloc, program.status) == (1, False)  # neither arrived nor asked again yet
    program.clock._now = 110.0  # noqa: SLF001
    program.scan()
    assert (program.currloc, program.status, program.xgoal, program.ygoal) == (1, True, 3.5, 7.5)  # same goal, busy again
    assert program.goals == [1, 0]  # a retry is not a new goal


def test_sequencer_gives_a_robot_whose_parking_failed_a_task():
    program = sequencer(x=7.9, y=4.5)
    program.scan()  # home is (7.9, 4.5)
    program.xgoal, program.ygoal = 7.9, 4.5
    program.xpos, program.ypos, program.status = 3.0, 3.0, False  # its drive home failed far from home
    program.tnext = 2
    program.scan()
    assert (program.currloc, program.tcurr, program.status) == (1, 2, True)


@pytest.mark.parametrize("tnext", [0, 3, 99])
def test_sequencer_ignores_no_task_or_an_unknown_task(tnext):
    program = sequencer()
    program.tnext = tnext
    program.scan()
    assert program.currloc == 0 and not program.status and program.goals == [0, 0]


# -- optimal assignment --------------------------------------------------------------------------


def optimal(robots: list[tuple[float, float]], compatible: list[list[int]], **task_values: list[float]) -> OptimalAssignment:
    program = make(OptimalAssignment, compatible=compatible)
    tasks = 2
    program.iBM, program.iFr = [40, 40], [30.0, 30.0]
    program.qSM, program.qSC = [0, 0], [100, 100]
    for name, values in TASKS.items():
        setattr(program, name, list(values))
    for name, values in task_values.items():
        setattr(program, name, values)
    program.cost = [0.0] * tasks
    program.xpos = [x for x, _ in robots]
    program.ypos = [y for _, y in robots]
    count = len(robots)
    program.loadcap, program.load = [20] * count, [0] * count
    program.currloc, program.tcurr, program.tnext = [0] * count, [0] * count, [0] * count
    return program


def test_optimal_sends_each_robot_to_the_task_beside_it():
    program = optimal([(17.0, 7.0), (4.0, 7.0)], [[1, 2], [1, 2]])
    program.scan()
    assert program.tnext == [2, 1]
    assert all(cost > 0 for cost in program.cost)


def test_optimal_respects_compatibility_and_full_storages():
    program = optimal([(4.0, 7.0), (4.2, 7.0)], [[2], [1, 2]])
    program.scan()
    assert program.tnext == [2, 1]  # both stand at task 1, but r01 may only serve task 2
    program = optimal([(4.0, 7.0)], [[1, 2]], qSM=[100, 0])
    program.scan()
    assert program.tnext == [2]  # task 1's storage is full


def test_optimal_leaves_busy_robots_alone_and_counts_what_they_will_take():
    program = optimal([(4.0, 7.0), (4.2, 7.0)], [[1, 2], [1, 2]], iBM=[20, 20])
    program.currloc = [1, 0]  # r01 is already on its way to task 1's source
    program.tcurr = [1, 0]
    program.scan()
    # r02 is next to task 1 too, but r01 will take its 20 items: task 2 is cheaper per item
    assert program.tnext == [0, 2]


def test_optimal_shares_a_task_when_there_are_more_robots_than_tasks():
    program = optimal([(4.0, 7.0), (4.1, 7.0), (4.2, 7.0)], [[1], [1], [1, 2]])
    program.scan()
    assert program.tnext[:2] == [1, 1]
    assert program.tnext[2] in (1, 2)


def test_optimal_gives_nothing_when_no_task_can_be_served():
    program = optimal([(4.0, 7.0)], [[]])
    program.scan()
    assert program.tnext == [0]
    assert not any(math.isnan(cost) for cost in program.cost)


def test_sequencer_parks_a_robot_left_without_work_and_a_task_takes_over():
    program = sequencer(x=7.9, y=4.5)
    program.park_after = 5.0
    clock = program.clock
    program.scan()  # first scan: (7.9, 4.5) is home
    program.tnext = 1
    program.scan()
    arrive(program)
    program.scan()
    program.loadstat = True
    program.scan()
    arrive(program)
    program.scan()
    program.loadstat = True
    program.scan()
    assert program.currloc == 0 and (program.xpos, program.ypos) == (1.8, 2.5)  # done, standing on task 1's destination
    program.tnext = 0
    clock._now = 100.0  # noqa: SLF001 (the simulated clock is stepped by hand here)
    program.scan()
    clock._now = 104.0  # noqa: SLF001
    program.scan()
    assert not program.status  # 4 s without work: stays
    clock._now = 105.0  # noqa: SLF001
    program.scan()
    assert (program.xgoal, program.ygoal, program.status, program.currloc) == (7.9, 4.5, True, 0)
    assert program.goals == [1, 0]  # parking is not a goal for a task
    program.xpos, program.ypos = 5.0, 3.5  # on its way home, a task arrives: it goes at once
    program.tnext = 2
    program.scan()
    assert (program.currloc, program.tcurr, program.xgoal, program.ygoal) == (1, 2, 18.5, 7.5)


def test_sequencer_without_park_after_stays_where_it_is():
    program = sequencer(x=1.8, y=2.5)
    program.clock._now = 1000.0  # noqa: SLF001
    program.scan()
    program.clock._now = 5000.0  # noqa: SLF001
    program.scan()
    assert not program.status and program.currloc == 0


def test_skip_full_leaves_full_storages_out_of_the_choice():
    program = make(TaskWeighting)
    _weighting_inputs(program, iBL=[100.0, 20.0], qSL=[100.0, 50.0])
    program.scan()
    assert program.tnext == [1]  # the thesis's formula still picks task 1 with a full storage
    program.skip_full = True
    program.scan()
    assert program.tnext == [2]
    _weighting_inputs(program, iBL=[100.0, 20.0], qSL=[100.0, 100.0])
    program.scan()
    assert program.tnext == [0]
    program = make(CooperativeDispatcher, compatible=[[1], [1, 2]], skip_full=True)
    _weighting_inputs(program, iBL=[100.0, 20.0], qSL=[100.0, 50.0], robots=2)
    program.scan()
    assert program.tnext == [0, 2]  # the dedicated robot has nothing left to do


def test_compatibility_from_the_fleets_files_is_thesis_table_7():
    program = make(CooperativeDispatcher, robots_file="robots/case2-sim2/robots.yaml", tasks_file="robots/case2-sim2/tasks.yaml",
                   robot_ids=["r01", "r02", "r03"], task_ids=["t01", "t02"])
    assert program.compatible == [[1], [2], [1, 2]]
    program = make(OptimalAssignment, robots_file="robots/case2-sim1/robots.yaml", tasks_file="robots/case2-sim1/tasks.yaml",
                   robot_ids=["r01", "r02"], task_ids=["t02", "t01"])
    assert program.compatible == [[1, 2], [1]]  # task numbers follow task_ids' order: t02 is task 1 here


def test_an_unknown_id_in_the_compatibility_files_is_named():
    with pytest.raises(KeyError, match="r09"):
        make(CooperativeDispatcher, robots_file="robots/robots.yaml", tasks_file="robots/tasks.yaml",
             robot_ids=["r09"], task_ids=["t01"])


# -- team sizes (max_team_size, programs/teams.py) -----------------------------------------------


def _robots_on(program: Program, tcurr: list[int], currloc: list[int]) -> None:
    program.tcurr, program.currloc = tcurr, currloc


def test_weighting_keeps_a_task_within_its_team_size():
    program = make(TaskWeighting, max_team=[0, 1])  # task 2 admits one robot at a time, task 1 any number
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0], robots=3)
    _robots_on(program, [0, 0, 0], [0, 0, 0])
    program.scan()
    assert program.tnext == [2, 1, 1]  # task 2 weighs least, but only the first robot may go
    _robots_on(program, [0, 2, 0], [0, 3, 0])  # r02 is on task 2 (carrying to its destination)
    program.scan()
    assert program.tnext == [1, 2, 1]  # the idle robots may not join it; r02 may stay on it next trip


def test_a_robot_waiting_for_a_place_gets_the_next_one_that_frees():
    program = make(TaskWeighting, max_team=[1, 1])
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0], robots=3)  # task 2 weighs least
    _robots_on(program, [1, 2, 0], [3, 1, 0])  # r01 on task 1, r02 on task 2, r03 idle: both teams full
    program.scan()
    # r03 waits for task 2; r02 is not promised task 2 again, or it would keep the place for ever
    assert program.tnext == [1, 0, 0]
    program.clock._now = 60.0  # noqa: SLF001
    _robots_on(program, [1, 2, 0], [3, 0, 0])  # r02 has unloaded: both r02 and r03 are idle
    program.scan()
    assert program.tnext == [1, 0, 2]  # r03 has waited longer


def test_cooperative_dispatcher_keeps_teams_within_their_size():
    program = make(CooperativeDispatcher, compatible=[[2], [1, 2], [1, 2]], max_team=[2, 2])
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0], robots=3)
    _robots_on(program, [2, 0, 0], [1, 0, 0])
    program.scan()
    assert program.tnext == [2, 2, 1]  # r01 (dedicated) and one more on task 2; the third goes to task 1


def test_svm_dispatcher_keeps_teams_within_their_size(tmp_path):
    from programs.svm_dispatcher import SvmDispatcher
    from softplc.svm.dataset import feature_names
    from softplc.svm.model import TaskModel

    TaskModel(features=feature_names(2), classes=[0, 1], coef=[[0.0] * 6], intercept=[-1.0]).save(tmp_path / "m.json")  # always task 1
    program = make(SvmDispatcher, model=str(tmp_path / "m.json"), max_team=[1, 0])
    program.iBL, program.qSL, program.sPD, program.tnext = [50.0, 50.0], [20.0, 20.0], [0.0, 0.0], [0, 0]
    _robots_on(program, [0, 0], [0, 0])
    program.scan()
    assert program.tnext == [1, 2]  # the second robot gets the model's other choice


def test_optimal_dispatcher_gives_a_task_no_more_places_than_its_team_has():
    program = optimal([(4.0, 7.0), (4.2, 7.0)], [[1, 2], [1, 2]])
    program.scan()
    assert program.tnext == [1, 1]  # no limit: both to the task beside them
    program = optimal([(4.0, 7.0), (4.2, 7.0)], [[1, 2], [1, 2]])
    program.max_team = [1, 0]
    program.scan()
    assert sorted(program.tnext) == [1, 2]
    program = optimal([(4.0, 7.0), (4.2, 7.0), (4.4, 7.0)], [[1, 2], [1, 2], [1]])
    program.max_team = [1, 1]
    program.tcurr, program.currloc = [1, 0, 0], [2, 0, 0]  # the first robot is loading at task 1
    program.scan()
    assert program.tnext == [0, 2, 0]  # task 1's one place is taken: the robot that serves only task 1 waits


def test_a_team_limit_without_the_robots_states_is_a_clear_fault():
    program = make(TaskWeighting, max_team=[1, 1])
    _weighting_inputs(program, iBL=[20.0, 60.0], qSL=[10.0, 10.0])
    with pytest.raises(ValueError, match="'max_team' needs 'tcurr' and 'currloc' bound"):
        program.scan()


def test_team_sizes_come_from_the_tasks_file():
    program = make(CooperativeDispatcher, robots_file="robots/robots.yaml", tasks_file="robots/tasks.yaml",
                   robot_ids=["r01", "r02", "r03"], task_ids=["t01", "t02"])
    assert program.max_team == [2, 2]
    program = make(OptimalAssignment, robots_file="robots/robots.yaml", tasks_file="robots/tasks.yaml",
                   robot_ids=["r01", "r02", "r03"], task_ids=["t02", "t01"])
    assert program.max_team == [2, 2]
