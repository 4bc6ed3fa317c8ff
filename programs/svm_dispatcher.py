"""SVM dispatcher (thesis case study III): a trained linear SVM picks the robot's next task.

Each scan the features [T1-in %, T1-out %, T1-demand %, T2-in %, T2-out %, T2-demand %] (the
tasks' iBL, qSL and sPD) go into the model; label 0 means task 1, label 1 task 2. Train a
model with `softplc svm label` and `softplc svm train`; `model` is the JSON file it writes (a
relative path is looked up from the working directory, then from the project folder).
With `skip_full: true` (not the thesis) a full output storage is never chosen, and with
`max_team` (one number per task, 0 = no limit; programs/teams.py) neither is a task whose team
is full: the robot gets the model's other choice (the other task) if that one can take it.
"""

from __future__ import annotations

from pathlib import Path

from programs.bindings import check_lengths
from programs.teams import Teams, assign, make_teams
from softplc import Input, Output, Param, Program
from softplc.svm.model import TaskModel

PROJECT = Path(__file__).resolve().parent.parent


def find_model(path: str) -> Path:
    """The model file: as given, else relative to the project folder."""
    candidate = Path(path)
    if candidate.is_absolute() or candidate.exists():
        return candidate
    return PROJECT / candidate


class SvmDispatcher(Program):
    iBL = Input("input buffer level % per task (tNN_iBL)")
    qSL = Input("output storage level % per task (tNN_qSL)")
    sPD = Input("current product demand % per task (tNN_sPD)")
    tnext = Output("task chosen for each robot's next trip (rNN_tnext)")
    svm_out = Output("the model's choice as a task number, for the records", optional=True)
    tcurr = Input("task each robot is serving (rNN_tcurr), to count teams for max_team", optional=True)
    currloc = Input("motion state of each robot (rNN_currloc), to count teams for max_team", optional=True)
    model = Param(description="trained model JSON (softplc svm train)")
    skip_full = Param(False, "never choose a task whose output storage is full (not the thesis)")
    max_team = Param([], "most robots serving each task at once, one number per task (0 or none: no limit)")

    def setup(self) -> None:
        self.classifier = TaskModel.load(find_model(self.model))  # a bad file faults the program with the reason
        self.teams: Teams | None = None
        self.checked = False

    def scan(self) -> None:
        tasks = check_lengths(self, "iBL", "qSL", "sPD")
        if not self.checked:
            check_lengths(self, "tnext", "tcurr", "currloc")
            self.teams = make_teams(self, tasks)
            self.checked = True
        features: list[float] = []
        for levels in zip(self.iBL, self.qSL, self.sPD):
            features += levels
        task = self.classifier.predict(features) + 1

        def pick(robot: int, room: list[int]) -> int:
            usable = [n for n in room if not (self.skip_full and self.qSL[n - 1] >= 100.0)]
            if task in usable:
                return task
            others = [n for n in usable if n != task]  # the model's other choice: with two tasks, the other one
            return others[0] if len(others) == 1 else 0

        self.tnext = assign(self.teams, self.now, len(self.tnext), self.tcurr, self.currloc, pick, range(1, tasks + 1))
        if self.svm_out is not None:
            self.svm_out = task
