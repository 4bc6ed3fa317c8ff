"""`softplc svm label | train | predict`: make training data, train a model, try it."""

from __future__ import annotations

import argparse
import random
import sys
from pathlib import Path
from typing import TextIO

from softplc.svm.dataset import (
    RULES,
    DatasetError,
    append_line,
    feature_names,
    format_line,
    generate,
    random_levels,
    read_dataset,
)
from softplc.svm.model import ESTIMATORS, ModelError, TaskModel, save_estimator, train
from softplc.util.plurals import plural

EXIT_OK, EXIT_FAILURE = 0, 1


def add_commands(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    svm = subparsers.add_parser(
        "svm",
        help="machine-learning dispatch: label training data, train a linear SVM",
        description="Training data and models for the SVM dispatcher (thesis case study III).",
    )
    commands = svm.add_subparsers(title="svm commands", metavar="COMMAND")

    label = commands.add_parser(
        "label",
        help="create training data (interactive, or scripted by a rule)",
        description="Show random level vectors [T1-in, T1-out, T1-demand, T2-in, ...] and record which task "
        "the robot should serve (label 0 = task 1, 1 = task 2), one 'label:f1,f2,...,' line each. "
        "Interactive in a terminal (answer 1 or 2, q to stop; lines are appended to FILE), or scripted "
        "with --rule for a reproducible data set.",
        epilog="Examples: softplc svm label train.txt | "
        "softplc svm label sim1.txt --rule balance --samples 312 --noise 0.05 --seed 1 | "
        "softplc svm label sim2.txt --rule demand --samples 1414 --demand 0:50 --demand 50:100 --noise 0.05 --seed 2",
    )
    label.add_argument("file", type=Path, help="training file to write (scripted) or append to (interactive)")
    label.add_argument("--rule", choices=sorted(RULES), help="label by a rule instead of asking: balance (fill the emptier "
                       "output that has input) or demand (balance plus the task's demand)")
    label.add_argument("--samples", type=int, default=312, help="number of samples with --rule (default 312)")
    label.add_argument("--seed", type=int, help="random seed (default: random interactively, 1 with --rule)")
    label.add_argument("--demand", action="append", metavar="LOW:HIGH",
                       help="demand range of the next task in %% (repeat per task; default 0:100 for two tasks)")
    label.add_argument("--noise", type=float, default=0.0, metavar="P",
                       help="with --rule: answer a random other task for a fraction P of the samples (default 0)")
    label.add_argument("--append", action="store_true", help="with --rule: append instead of overwriting")
    label.set_defaults(func=cmd_label)

    fit = commands.add_parser(
        "train",
        help="train a linear SVM from a training file",
        description="Fit scikit-learn's linear SVM (C = 1 by default) on FILE, print the training accuracy and the "
        "k-fold cross-validated accuracy, and save the model as MODEL.json (read by the SVM dispatcher) and "
        "MODEL.joblib (the fitted estimator).",
        epilog="Example: softplc svm train train.txt --out model",
    )
    fit.add_argument("file", type=Path, help="training file (label:f1,f2,...,)")
    fit.add_argument("--out", type=Path, help="model path without extension (default: FILE without .txt, + -model)")
    fit.add_argument("--C", dest="c", type=float, default=1.0, help="regularisation C (default 1)")
    fit.add_argument("--estimator", choices=ESTIMATORS, default="svc", help="svc: SVC(kernel='linear') as the thesis (default); linearsvc")
    fit.add_argument("--folds", type=int, default=5, help="cross-validation folds (default 5)")
    fit.set_defaults(func=cmd_train)

    predict = commands.add_parser("predict", help="the task a model picks for a feature vector",
                                  description="Print the task (1, 2, ...) MODEL picks for FEATURES.",
                                  epilog="Example: softplc svm predict model.json 20,10,30,5,5,0")
    predict.add_argument("model", type=Path, help="model JSON file")
    predict.add_argument("features", help="comma-separated features, e.g. 20,10,30,5,5,0")
    predict.set_defaults(func=cmd_predict)


def _demand_ranges(values: list[str] | None) -> list[tuple[int, int]]:
    if not values:
        return [(0, 100), (0, 100)]
    ranges = []
    for value in values:
        low, colon, high = value.partition(":")
        try:
            pair = (int(low), int(high))
        except ValueError:
            raise ValueError(f"--demand {value!r}: write LOW:HIGH in %, e.g. 0:50") from None
        if not colon or not 0 <= pair[0] <= pair[1] <= 100:
            raise ValueError(f"--demand {value!r}: need 0 <= LOW <= HIGH <= 100")
        ranges.append(pair)
    if len(ranges) < 2:
        raise ValueError("give --demand once per task (at least two tasks)")
    return ranges


def cmd_label(args: argparse.Namespace) -> int:
    try:
        ranges = _demand_ranges(args.demand)
    except ValueError as error:
        print(f"softplc svm label: {error}", file=sys.stderr)
        return EXIT_FAILURE
    if args.rule:
        if args.samples < 1 or not 0 <= args.noise < 1:
            print("softplc svm label: --samples must be at least 1 and --noise between 0 and 1", file=sys.stderr)
            return EXIT_FAILURE
        dataset = generate(args.samples, RULES[args.rule], ranges, 1 if args.seed is None else args.seed, args.noise)
        text = "".join(format_line(label, features) + "\n" for label, features in zip(dataset.labels, dataset.features))
        with open(args.file, "a" if args.append else "w") as file:
            file.write(text)
        counts = ", ".join(f"task {task + 1}: {dataset.labels.count(task)}" for task in range(len(ranges)))
        print(f"{args.file}: {plural(len(dataset), 'sample')} labelled by rule '{args.rule}' ({counts})")
        return EXIT_OK
    if not sys.stdin.isatty():
        print("softplc svm label: interactive labelling needs a terminal; use --rule for scripted labelling", file=sys.stderr)
        return EXIT_FAILURE
    return _interactive(args.file, ranges, random.Random(args.seed), sys.stdin, sys.stdout)


def _bar(value: float, width: int = 25) -> str:
    filled = round(width * value / 100)
    return "#" * filled + "." * (width - filled)


def _interactive(path: Path, ranges: list[tuple[int, int]], rng: random.Random, stdin: TextIO, stdout: TextIO) -> int:
    names = feature_names(len(ranges))
    tasks = len(ranges)
    choices = "/".join(str(task) for task in range(1, tasks + 1))
    print(f"Labelling into {path}: which task should the robot serve? Answer {choices}; q (or end of input) stops.", file=stdout)
    count = 0
    while True:
        vector = random_levels(rng, ranges)
        print(f"\nsample {count + 1}", file=stdout)
        for name, value in zip(names, vector):
            print(f"  {name:<10} {_bar(value)} {value:3d} %", file=stdout)
        while True:
            print(f"assign to task [{choices}/q]: ", end="", file=stdout, flush=True)
            answer = stdin.readline()
            if not answer or answer.strip().lower() in ("q", "quit"):
                print(f"\n{plural(count, 'sample')} added to {path}", file=stdout)
                return EXIT_OK
            if answer.strip().isdigit() and 1 <= int(answer) <= tasks:
                break
            print(f"  please answer {choices} or q", file=stdout)
        append_line(path, int(answer) - 1, vector)
        count += 1


def cmd_train(args: argparse.Namespace) -> int:
    try:
        dataset = read_dataset(args.file)
        model, fitted = train(dataset, C=args.c, estimator=args.estimator, folds=args.folds)
    except (DatasetError, ModelError) as error:
        print(f"softplc svm train: {error}", file=sys.stderr)
        return EXIT_FAILURE
    base = args.out or args.file.with_name(args.file.stem + "-model")
    json_path, joblib_path = base.with_suffix(".json"), base.with_suffix(".joblib")
    model.save(json_path)
    save_estimator(fitted, joblib_path)
    counts = ", ".join(f"task {int(label) + 1}: {n}" for label, n in model.class_counts.items())
    print(f"{args.file}: {plural(model.samples, 'sample')} ({counts}), features {', '.join(model.features)}")
    print(f"model: {model.estimator} linear, C = {model.C:g}")
    print(f"training accuracy:        {model.train_accuracy:.3f}")
    if model.cv_folds:
        print(f"cross-validated accuracy: {model.cv_accuracy:.3f} ({model.cv_folds}-fold)")
    else:
        print("cross-validated accuracy: not computed (too few samples of one task)")
    print(f"saved {json_path} and {joblib_path}")
    return EXIT_OK


def cmd_predict(args: argparse.Namespace) -> int:
    try:
        model = TaskModel.load(args.model)
        features = [float(item) for item in args.features.split(",") if item.strip()]
        label = model.predict(features)
    except ValueError as error:  # ModelError, or a feature that is not a number
        print(f"softplc svm predict: {error}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"task {label + 1}")
    return EXIT_OK
