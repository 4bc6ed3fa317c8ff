"""Team sizes for dispatchers: at most `max_team` robots serve a task at once (thesis §4.7.2, SPEC §3).

A robot serves a task from the moment it is sent to the task's source until it has unloaded
at the destination: `tcurr` = the task's number and `currloc` 1–4. Every dispatcher gives a
robot only a task whose team has room for it, counting the robots already on it and those it
has just given the task to in the same decision. `max_team` has one number per task (task
order); 0, or no number, means no limit — the default when a task states no `max_team_size`.

Idle robots choose first, the one waiting longest first; a robot on a trip is then promised
its next task only where that leaves room for the robots still waiting (see `Teams`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from softplc import Program

NO_LIMIT = 0
ON_A_TRIP = (1, 2, 3, 4)  # currloc: on the way to / at the source or the destination

Choose = Callable[[int, list[int]], int]  # (robot index, task numbers open to it) -> task number, 0: none


def make_teams(program: Program, tasks: int) -> Teams | None:
    """Teams for the program's `max_team` (None when no task is limited); ValueError if they cannot be counted."""
    limits = [int(limit) for limit in program.max_team] + [NO_LIMIT] * max(0, tasks - len(program.max_team))
    if len(limits) > tasks:
        raise ValueError(f"'max_team' has {len(limits)} numbers for {tasks} tasks: give one per task, in the task order")
    if all(limit <= NO_LIMIT for limit in limits):
        return None
    if program.tcurr is None or program.currloc is None:
        raise ValueError("'max_team' needs 'tcurr' and 'currloc' bound (one tag per robot, in the order of 'tnext') "
                         "to count the robots on each task")
    return Teams(limits)


def members(tcurr: Sequence[int], currloc: Sequence[int], tasks: int) -> list[int]:
    """How many robots are on each task now (index = task number - 1)."""
    counts = [0] * tasks
    for task, state in zip(tcurr, currloc):
        if state in ON_A_TRIP and 1 <= task <= tasks:
            counts[task - 1] += 1
    return counts


class Teams:
    """Gives robots tasks whose team has room: idle robots first (longest waiting first), then previews.

    A robot on a trip also gets a `tnext` (its next task, which its sequencer takes as soon as
    the trip ends). It is not counted twice on its own task, but it is not promised a place an
    idle robot is waiting for either: that robot gets it at the next decision.
    """

    def __init__(self, limits: list[int]) -> None:
        self.limits = limits
        self.idle_since: dict[int, float] = {}

    def has_room(self, task: int, counts: list[int]) -> bool:
        limit = self.limits[task - 1]
        return limit <= NO_LIMIT or counts[task - 1] < limit

    def assign(self, now: float, tcurr: Sequence[int], currloc: Sequence[int], choose: Choose, candidates: Sequence[int]) -> list[int]:
        """`tnext` for every robot: `choose` picks among the tasks whose team has room for that robot."""
        tasks = len(self.limits)
        counts = members(tcurr, currloc, tasks)
        busy = [robot for robot in range(len(currloc)) if currloc[robot] in ON_A_TRIP]
        for robot in range(len(currloc)):
            if robot in busy:
                self.idle_since.pop(robot, None)
            else:
                self.idle_since.setdefault(robot, now)
        idle = sorted(self.idle_since, key=lambda robot: (self.idle_since[robot], robot))
        chosen = [0] * len(currloc)
        waiting = [0] * tasks  # idle robots left without a place, by the task they would take
        for robot in idle:
            task = choose(robot, [t for t in candidates if self.has_room(t, counts)])
            if task:
                counts[task - 1] += 1  # its place is taken for the rest of this decision
            else:
                wish = choose(robot, list(candidates))
                if wish:
                    waiting[wish - 1] += 1
            chosen[robot] = task
        for robot in busy:
            own = tcurr[robot]
            # not counted twice on its own task; the places idle robots wait for are not promised
            promised = [count - (number == own) + wished for number, (count, wished) in enumerate(zip(counts, waiting), 1)]
            task = choose(robot, [t for t in candidates if self.has_room(t, promised)])
            if task and task != own:
                counts[task - 1] += 1
            chosen[robot] = task
        return chosen


def assign(teams: Teams | None, now: float, robots: int, tcurr: Sequence[int] | None, currloc: Sequence[int] | None,
           choose: Choose, candidates: Sequence[int]) -> list[int]:
    """`tnext` for `robots` robots: through `teams` when tasks have limits, else `choose` among every candidate."""
    if teams is None or tcurr is None or currloc is None:
        return [choose(robot, list(candidates)) for robot in range(robots)]
    return teams.assign(now, tcurr, currloc, choose, candidates)
