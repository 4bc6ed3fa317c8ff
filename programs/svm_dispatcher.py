"""SVM dispatcher (thesis case study III): a trained linear SVM picks the robot's next task.

Each scan the features [T1-in %, T1-out %, T1-demand %, T2-in %, T2-out %, T2-demand %] (the
tasks' iBL, qSL and sPD) go into the model; label 0 means task 1, label 1 task 2. Train a
model with `softplc svm label` and `softplc svm train`; `model` is the JSON file it writes (a
relative path is looked up from the working directory, then from the project folder).
With `skip_full: true` (not the thesis) a full output storage is never chosen.
"""

from __future__ import annotations

from pathlib import Path

from programs.bindings import check_lengths
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
    model = Param(description="trained model JSON (softplc svm train)")
    skip_full = Param(False, "never choose a task whose output storage is full (not the thesis)")

    def setup(self) -> None:
        self.classifier = TaskModel.load(find_model(self.model))  # a bad file faults the program with the reason

    def scan(self) -> None:
        check_lengths(self, "iBL", "qSL", "sPD")
        features: list[float] = []
        for levels in zip(self.iBL, self.qSL, self.sPD):
            features += levels
        task = self.classifier.predict(features) + 1
        if self.skip_full and self.qSL[task - 1] >= 100.0:
            # the model's other choice: with two tasks, the other one, if it has room
            others = [n for n, level in enumerate(self.qSL, 1) if n != task and level < 100.0]
            task = others[0] if len(others) == 1 else 0
        self.tnext = [task] * len(self.tnext)
        if self.svm_out is not None:
            self.svm_out = task
