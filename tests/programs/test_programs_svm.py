"""Case III: SVM training data, models, the `softplc svm` commands and the SVM dispatcher."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO

from softplc.app.cli import main
from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock
from softplc.svm.dataset import (
    DatasetError,
    balance_rule,
    demand_rule,
    feature_names,
    format_line,
    generate,
    parse_lines,
    read_dataset,
)
from softplc.svm.model import ModelError, TaskModel, train

SOFTPLC = [sys.executable, "-m", "softplc.app.cli"]
MODELS = REPO / "scenarios" / "svm"


def test_training_lines_round_trip_in_the_thesis_format():
    assert format_line(1, [20, 10, 30, 5, 5, 0]) == "1:20,10,30,5,5,0,"
    dataset = parse_lines(["1:20,10,30,5,5,0,", "", "# a comment", "0:1.5,2,3,4,5,6,"])
    assert dataset.labels == [1, 0]
    assert dataset.features == [[20, 10, 30, 5, 5, 0], [1.5, 2, 3, 4, 5, 6]]
    assert dataset.tasks == 2
    assert feature_names(2) == ["T1-in", "T1-out", "T1-demand", "T2-in", "T2-out", "T2-demand"]


@pytest.mark.parametrize("line, message", [
    ("1;2,3,4,5,6,7,", "no ':'"),
    ("x:1,2,3,4,5,6,", "not a number"),
    ("1:1,2,3,4,5,", "expected 3 per task"),
    ("-1:1,2,3,4,5,6,", "negative"),
])
def test_bad_training_lines_are_named(line, message):
    with pytest.raises(DatasetError, match=message) as error:
        parse_lines(["0:1,2,3,4,5,6,", line], "train.txt")
    assert "train.txt:2:" in str(error.value)


def test_lines_of_different_widths_are_refused():
    with pytest.raises(DatasetError, match="earlier lines have 6"):
        parse_lines(["0:1,2,3,4,5,6,", "1:1,2,3,4,5,6,7,8,9,"])


def test_labelling_rules_follow_the_thesis_example():
    # thesis: T1-out 40 %, T2-out 20 % (inputs equal) → task 2, "since the robot will be required to fill that buffer"
    assert balance_rule([50, 40, 0, 50, 20, 0]) == 1
    # ... but not when task 2's input buffer is empty
    assert balance_rule([80, 40, 0, 0, 20, 0]) == 0
    # the demand rule sends the robot where demand is high
    assert balance_rule([50, 20, 0, 50, 30, 90]) == 0
    assert demand_rule([50, 20, 0, 50, 30, 90]) == 1


def test_generated_data_sets_repeat_and_keep_demand_in_range():
    first = generate(200, demand_rule, [(0, 50), (50, 100)], seed=3, noise=0.1)
    again = generate(200, demand_rule, [(0, 50), (50, 100)], seed=3, noise=0.1)
    assert first == again
    assert all(0 <= row[2] <= 50 and 50 <= row[5] <= 100 for row in first.features)
    clean = generate(200, demand_rule, [(0, 50), (50, 100)], seed=3)
    flipped = sum(a != b for a, b in zip(first.labels, clean.labels))
    assert 5 <= flipped <= 40  # about 10 % of 200


@pytest.mark.parametrize("estimator", ["svc", "linearsvc"])
def test_model_predicts_exactly_what_scikit_learn_predicts(estimator, tmp_path):
    dataset = generate(300, balance_rule, [(0, 100), (0, 100)], seed=5, noise=0.05)
    model, fitted = train(dataset, estimator=estimator)
    ours = [model.predict(row) for row in dataset.features]
    theirs = fitted.predict(np.asarray(dataset.features)).tolist()
    assert ours == theirs
    assert 0.85 < model.train_accuracy <= 1.0 and 0.8 < model.cv_accuracy <= 1.0 and model.cv_folds == 5
    model.save(tmp_path / "m.json")
    loaded = TaskModel.load(tmp_path / "m.json")
    assert loaded == model


def test_training_needs_two_tasks_and_bad_model_files_are_explained(tmp_path):
    dataset = parse_lines(["0:1,2,3,4,5,6,", "0:6,5,4,3,2,1,"])
    with pytest.raises(ModelError, match="needs two tasks"):
        train(dataset)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ModelError, match="not a model JSON"):
        TaskModel.load(tmp_path / "bad.json")
    (tmp_path / "other.json").write_text('{"features": ["a"], "classes": [0, 1], "coef": [[1, 2]], "intercept": [0]}')
    with pytest.raises(ModelError, match="do not match"):
        TaskModel.load(tmp_path / "other.json")
    with pytest.raises(ModelError, match="cannot read"):
        TaskModel.load(tmp_path / "missing.json")


def test_shipped_models_match_their_training_files():
    for name, samples in (("case3-sim1", 312), ("case3-sim2", 1414)):
        dataset = read_dataset(MODELS / f"{name}-train.txt")
        model = TaskModel.load(MODELS / f"{name}-model.json")
        assert len(dataset) == samples == model.samples
        assert model.features == feature_names(2) and model.estimator == "svc" and model.C == 1.0
        assert model.class_counts == {str(label): dataset.labels.count(label) for label in (0, 1)}
    dataset = read_dataset(MODELS / "case3-sim1-train.txt")
    retrained, _ = train(dataset, folds=0)  # the small set: retraining gives the shipped weights
    model = TaskModel.load(MODELS / "case3-sim1-model.json")
    assert retrained.coef[0] == pytest.approx(model.coef[0]) and retrained.intercept == pytest.approx(model.intercept)
    sim2 = TaskModel.load(MODELS / "case3-sim2-model.json")
    # equal levels, task 2 in high demand: the sim-2 model goes to task 2
    assert sim2.predict([50, 10, 25, 50, 10, 75]) == 1


# -- the dispatcher in a runtime ----------------------------------------------------------------

DISPATCH = """
version: 1
tags:
  svm_out: {type: uint16}
templates:
  task:
    instances: [t01, t02]
    tags:
      iBL: {type: float32}
      qSL: {type: float32}
      sPD: {type: float32}
    initial:
      t01: {iBL: 60, qSL: LEVEL1}
      t02: {iBL: 60, qSL: 50}
  robot:
    instances: [r01]
    tags:
      tnext: {type: uint16}
tasks:
  dispatch:
    interval: 1s
    programs:
      - name: svm
        program: programs.svm_dispatcher:SvmDispatcher
        bind: {iBL: [t01_iBL, t02_iBL], qSL: [t01_qSL, t02_qSL], sPD: [t01_sPD, t02_sPD], tnext: [r01_tnext], svm_out: svm_out}
        params: {model: MODEL}
"""


@pytest.mark.parametrize("level1, task", [(80, 2), (0, 1)])
async def test_svm_dispatcher_sends_the_robot_where_the_model_says(make_config, tmp_path, level1, task):
    text = DISPATCH.replace("LEVEL1", str(level1)).replace("MODEL", "scenarios/svm/case3-sim1-model.json")
    runtime = Runtime(make_config(text), SimClock(), state_dir=tmp_path)
    await runtime.run(duration=2)
    assert runtime.db.value("r01_tnext") == task
    assert runtime.db.value("svm_out") == task


async def test_svm_dispatcher_with_a_missing_model_faults_with_the_reason(make_config, tmp_path):
    text = DISPATCH.replace("LEVEL1", "10").replace("MODEL", str(tmp_path / "nope.json"))
    runtime = Runtime(make_config(text), SimClock(), state_dir=tmp_path)
    await runtime.run(duration=2)
    instance = runtime.program("svm")
    assert instance.state.value == "FAULTED"
    assert "nope.json" in instance.error
    assert runtime.tasks[0].stats.cycles >= 2  # the runtime kept scanning


# -- softplc svm label / train / predict ---------------------------------------------------------


class Done:
    """What a command printed and returned."""

    def __init__(self, returncode: int, stdout: str, stderr: str) -> None:
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


def run_cli(*args: str, cwd: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> Done:
    """`softplc ARGS` in this process (the same main() the console script calls)."""
    monkeypatch.chdir(cwd)
    code = main(list(args))
    captured = capsys.readouterr()
    return Done(code, captured.out, captured.err)


def test_label_train_predict_from_the_command_line(tmp_path, capsys, monkeypatch):
    cli = {"cwd": tmp_path, "capsys": capsys, "monkeypatch": monkeypatch}
    done = run_cli("svm", "label", "train.txt", "--rule", "demand", "--samples", "120", "--demand", "0:50",
                   "--demand", "50:100", "--seed", "4", **cli)
    assert done.returncode == 0, done.stderr
    assert "120 samples labelled by rule 'demand'" in done.stdout
    lines = (tmp_path / "train.txt").read_text().splitlines()
    assert len(lines) == 120 and all(line.endswith(",") and line[1] == ":" for line in lines)
    done = run_cli("svm", "train", "train.txt", "--out", "model", **cli)
    assert done.returncode == 0, done.stderr
    assert "training accuracy:" in done.stdout and "cross-validated accuracy:" in done.stdout
    assert (tmp_path / "model.json").exists() and (tmp_path / "model.joblib").exists()
    done = run_cli("svm", "predict", "model.json", "50,10,10,50,10,90", **cli)
    assert done.returncode == 0 and done.stdout.strip() == "task 2"
    done = run_cli("svm", "predict", "model.json", "1,2,3", **cli)
    assert done.returncode == 1 and "takes 6 features" in done.stderr


def test_train_reports_a_bad_file_without_a_traceback(tmp_path, capsys, monkeypatch):
    (tmp_path / "train.txt").write_text("0:1,2,3,4,5,6,\n1:oops\n")
    done = run_cli("svm", "train", "train.txt", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert done.returncode == 1
    assert "train.txt:2: not a number" in done.stderr and "Traceback" not in done.stderr


def test_interactive_labelling_needs_a_terminal(tmp_path):
    done = subprocess.run([*SOFTPLC, "svm", "label", "t.txt"], cwd=tmp_path, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=60, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 1 and "needs a terminal" in done.stderr


def test_interactive_labelling_in_a_terminal(tmp_path):
    controller, terminal = pty.openpty()
    process = subprocess.Popen([*SOFTPLC, "svm", "label", "t.txt", "--seed", "9"], cwd=tmp_path, stdin=terminal,
                               stdout=terminal, stderr=terminal, env={**os.environ, "PYTHONPATH": str(REPO)})
    os.close(terminal)
    output = b""

    def read_until(count: int, text: bytes, timeout: float = 30.0) -> None:
        nonlocal output
        deadline = time.monotonic() + timeout
        while output.count(text) < count:
            assert time.monotonic() < deadline, f"waited for {text!r} x{count}; got {output[-400:]!r}"
            ready, _, _ = select.select([controller], [], [], 0.1)
            if ready:
                output += os.read(controller, 4096)

    prompt = b"assign to task [1/2/q]"
    try:
        # "7" is not a task: asked again for the same sample
        for count, answer in enumerate((b"1\n", b"7\n", b"2\n", b"q\n"), 1):
            read_until(count, prompt)
            os.write(controller, answer)
        read_until(1, b"2 samples added")
        assert process.wait(timeout=30) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        os.close(controller)
    assert b"please answer 1/2 or q" in output and b"T2-demand" in output
    lines = (tmp_path / "t.txt").read_text().splitlines()
    assert [line[:2] for line in lines] == ["0:", "1:"]


def test_svm_dispatcher_with_skip_full_never_picks_a_full_storage(tmp_path):
    from programs.svm_dispatcher import SvmDispatcher
    from softplc.core.program import ProgramContext

    always_task_1 = TaskModel(features=feature_names(2), classes=[0, 1], coef=[[0.0] * 6], intercept=[-1.0])
    always_task_1.save(tmp_path / "m.json")
    program = SvmDispatcher(ProgramContext("svm", SimClock(), {"model": str(tmp_path / "m.json"), "skip_full": True}))
    program.setup()
    program.iBL, program.sPD, program.tnext, program.svm_out = [50.0, 50.0], [0.0, 0.0], [0], 0
    program.tcurr = program.currloc = None  # unbound, as the runtime leaves them
    for levels, task in (([20.0, 20.0], 1), ([100.0, 20.0], 2), ([100.0, 100.0], 0)):
        program.qSL = levels
        program.scan()
        assert program.tnext == [task]
