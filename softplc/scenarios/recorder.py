"""The run's records: the thesis's three files (XY_, LEV_, TSK_) and the counters behind the summary.

Sampled at scan-cycle boundaries on the simulated clock, so two runs of a scenario give the
same rows. `observe()` runs after every cycle (it integrates idle time and counts trips);
`sample()` appends a row to each record every `every` seconds.

- XY_<name>.csv:  time, then x and y of every robot;
- LEV_<name>.csv: time, every task's input and output level (%), task weight (or cost),
  demand (%), and the SVM's choice when there is one;
- TSK_<name>.csv: time, goals issued per task, and their total.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

from softplc.core.tagdb import TagDatabase

WAITING, TO_SOURCE, TO_DESTINATION, AT_DESTINATION = 0, 1, 3, 4
PROGRESSING = ("moving", "planning")  # navigation states of a robot getting on with its trip
STUCK_AFTER = 1.0  # s: shorter stops (the cycle between arriving and being taken, a brief yield) are not stuck


@dataclass
class RobotRecord:
    """What one robot did: trips per task, items delivered, idle and stuck seconds, distance driven."""

    trips: dict[int, int] = field(default_factory=dict)
    delivered: dict[int, int] = field(default_factory=dict)
    idle: float = 0.0
    # On the way to a station but not getting on with it for more than STUCK_AFTER (blocked,
    # waiting for a station, failed, or stopped and not taken as arrived): the time, longest stretch.
    stuck: float = 0.0
    stuck_run: float = 0.0
    longest_stuck: float = 0.0
    distance: float = 0.0
    failures: int = 0  # times its navigation gave up on a goal (navstate "failed")
    last_navstate: str = ""
    last_currloc: int = 0
    last_load: int = 0
    last_xy: tuple[float, float] = (0.0, 0.0)


class Recorder:
    """Samples a running plant into the three records and keeps per-robot counters."""

    def __init__(self, db: TagDatabase, robots: list[str], tasks: list[str], *, every: float = 1.0, svm: bool = False) -> None:
        self.db = db
        self.robots = robots
        self.tasks = tasks
        self.every = every
        self.svm = svm
        self.next_sample = 0.0
        self.last_time: float | None = None
        self.full_at: dict[str, float] = {}
        self.trip_log: list[tuple[float, str, int]] = []  # (time the goal was issued, robot, task number)
        self.robot_records = {robot: RobotRecord() for robot in robots}
        for robot in robots:
            record = self.robot_records[robot]
            record.last_xy = (db.value(f"{robot}_xpos"), db.value(f"{robot}_ypos"))
        numbers = range(1, len(tasks) + 1)
        self.xy_header = ["time"] + [f"{robot}_{axis}" for robot in robots for axis in ("x", "y")]
        self.lev_header = (["time"] + [f"T{n}-in" for n in numbers] + [f"T{n}-out" for n in numbers]
                           + [f"T{n}-wt" for n in numbers] + [f"T{n}-D" for n in numbers] + (["SVM-out"] if svm else []))
        self.tsk_header = ["time"] + [f"T{n}count" for n in numbers] + ["total"]
        self.xy: list[list[str]] = []
        self.lev: list[list[str]] = []
        self.tsk: list[list[str]] = []

    def observe(self, now: float) -> None:
        """Called after every scan cycle: integrate idle time, count trips and deliveries."""
        value = self.db.value
        dt = 0.0 if self.last_time is None else now - self.last_time
        self.last_time = now
        for robot, record in self.robot_records.items():
            currloc = value(f"{robot}_currloc")
            if record.last_currloc == WAITING:
                record.idle += dt  # it spent the last interval without a task (waiting, or parking)
            if record.last_currloc in (TO_SOURCE, TO_DESTINATION) and record.last_navstate not in PROGRESSING:
                record.stuck_run += dt
                if record.stuck_run > STUCK_AFTER:  # the whole stretch counts, once it is not a hand-over
                    record.stuck += dt if record.stuck_run - dt > STUCK_AFTER else record.stuck_run
                    record.longest_stuck = max(record.longest_stuck, record.stuck_run)
            else:
                record.stuck_run = 0.0
            task = value(f"{robot}_tcurr")
            if currloc == TO_SOURCE and record.last_currloc != TO_SOURCE:
                record.trips[task] = record.trips.get(task, 0) + 1
                self.trip_log.append((now, robot, task))
            load = value(f"{robot}_load")
            if currloc == AT_DESTINATION and load < record.last_load:
                record.delivered[task] = record.delivered.get(task, 0) + record.last_load - load
            xy = (value(f"{robot}_xpos"), value(f"{robot}_ypos"))
            record.distance += ((xy[0] - record.last_xy[0]) ** 2 + (xy[1] - record.last_xy[1]) ** 2) ** 0.5
            record.last_xy = xy
            record.last_currloc, record.last_load = currloc, load
            navstate = value(f"{robot}_navstate")
            if navstate == "failed" and record.last_navstate != "failed":
                record.failures += 1
            record.last_navstate = navstate
        for task in self.tasks:
            if task not in self.full_at and value(f"{task}_qSL") >= 100.0:
                self.full_at[task] = now
        if now >= self.next_sample:
            self.sample(now)
            while self.next_sample <= now:
                self.next_sample += self.every

    def sample(self, now: float) -> None:
        """Append one row to each record."""
        value = self.db.value
        time = f"{now:.3f}"
        self.xy.append([time] + [f"{value(f'{robot}_{axis}pos'):.4f}" for robot in self.robots for axis in ("x", "y")])
        levels = ([f"{value(f'{task}_iBL'):.2f}" for task in self.tasks] + [f"{value(f'{task}_qSL'):.2f}" for task in self.tasks]
                  + [f"{value(f'{task}_Tw'):.6g}" for task in self.tasks] + [f"{value(f'{task}_sPD'):.0f}" for task in self.tasks])
        if self.svm:
            levels.append(str(value("svm_out")))
        self.lev.append([time] + levels)
        goals = [value(f"{task}_goals") for task in self.tasks]
        self.tsk.append([time] + [str(count) for count in goals] + [str(sum(goals))])

    def write(self, directory: Path, name: str) -> dict[str, Path]:
        """Write XY_, LEV_ and TSK_ CSV files into `directory`; return their paths by record."""
        directory.mkdir(parents=True, exist_ok=True)
        paths = {}
        for record, header, rows in (("XY", self.xy_header, self.xy), ("LEV", self.lev_header, self.lev), ("TSK", self.tsk_header, self.tsk)):
            buffer = io.StringIO()
            writer = csv.writer(buffer, lineterminator="\n")
            writer.writerow(header)
            writer.writerows(rows)
            path = directory / f"{record}_{name}.csv"
            path.write_text(buffer.getvalue())
            paths[record] = path
        return paths
