"""SVM training data: the thesis's `train.txt` format, random level vectors and labelling rules.

A line is `label:f1,f2,f3,f4,f5,f6,` — label 0 → task 1, 1 → task 2 — with the features in
the order [T1-in %, T1-out %, T1-demand %, T2-in %, T2-out %, T2-demand %] (three per task,
so more tasks simply make longer lines). The thesis labelled random vectors by hand; a
`Rule` labels them by a formula instead, so a data set can be regenerated exactly.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

FEATURES_PER_TASK = ("in", "out", "demand")


def feature_names(tasks: int = 2) -> list[str]:
    """['T1-in', 'T1-out', 'T1-demand', 'T2-in', ...] for `tasks` tasks."""
    return [f"T{task}-{kind}" for task in range(1, tasks + 1) for kind in FEATURES_PER_TASK]


class DatasetError(ValueError):
    """A training file line that cannot be read; the message says which line and why."""


@dataclass
class Dataset:
    """Labelled feature vectors (labels are 0-based task indices)."""

    features: list[list[float]]
    labels: list[int]

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def tasks(self) -> int:
        return len(self.features[0]) // len(FEATURES_PER_TASK) if self.features else 0


def format_line(label: int, features: Sequence[float]) -> str:
    """One training line, e.g. '1:20,10,30,5,5,0,'."""
    return f"{label}:" + "".join(f"{_number(value)}," for value in features)


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else repr(float(value))


def parse_lines(lines: Sequence[str], source: str = "<data>") -> Dataset:
    """Read training lines; raise DatasetError naming the first bad line."""
    features: list[list[float]] = []
    labels: list[int] = []
    width = None
    for number, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        label_text, colon, rest = line.partition(":")
        if not colon:
            raise DatasetError(f"{source}:{number}: expected 'label:f1,f2,...,' but found no ':' in {line!r}")
        try:
            label = int(label_text)
            values = [float(item) for item in rest.split(",") if item.strip()]
        except ValueError:
            raise DatasetError(f"{source}:{number}: not a number in {line!r}") from None
        if label < 0:
            raise DatasetError(f"{source}:{number}: label {label} is negative (0 = task 1, 1 = task 2)")
        if not values or len(values) % len(FEATURES_PER_TASK):
            raise DatasetError(f"{source}:{number}: {len(values)} features; expected 3 per task (in, out, demand)")
        if width is not None and len(values) != width:
            raise DatasetError(f"{source}:{number}: {len(values)} features, but earlier lines have {width}")
        width = len(values)
        features.append(values)
        labels.append(label)
    return Dataset(features, labels)


def read_dataset(path: str | Path) -> Dataset:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise DatasetError(f"cannot read {path}: {error.strerror or error}") from None
    dataset = parse_lines(text.splitlines(), str(path))
    if not dataset.labels:
        raise DatasetError(f"{path}: no training lines")
    return dataset


def append_line(path: str | Path, label: int, features: Sequence[float]) -> None:
    with open(path, "a") as file:
        file.write(format_line(label, features) + "\n")


# -- random level vectors and scripted labelling ---------------------------------------------


def random_levels(rng: random.Random, demand_ranges: Sequence[tuple[int, int]]) -> list[int]:
    """A random vector as the thesis's GUI drew it: whole percentages, demand within its range."""
    vector: list[int] = []
    for low, high in demand_ranges:
        vector += [rng.randint(0, 100), rng.randint(0, 100), rng.randint(low, high)]
    return vector


Rule = Callable[[Sequence[float]], int]


def _scores(features: Sequence[float], demand_weight: float) -> list[float]:
    # A task needs the robot more when its output storage is low, but only if its input
    # buffer has material to carry; demand (when used) adds to the need.
    scores = []
    for task in range(len(features) // 3):
        level_in, level_out, demand = features[3 * task: 3 * task + 3]
        scores.append(0.5 * level_in - level_out + demand_weight * demand)
    return scores


def _best(scores: list[float]) -> int:
    return max(range(len(scores)), key=lambda task: (scores[task], -task))  # ties → lower task


def balance_rule(features: Sequence[float]) -> int:
    """Unbiased (thesis case III sim 1): fill the emptier output storage that has input."""
    return _best(_scores(features, 0.0))


def demand_rule(features: Sequence[float]) -> int:
    """Demand-driven (thesis case III sim 2): as `balance`, plus the task's demand."""
    return _best(_scores(features, 1.0))


RULES: dict[str, Rule] = {"balance": balance_rule, "demand": demand_rule}


def generate(samples: int, rule: Rule, demand_ranges: Sequence[tuple[int, int]], seed: int, noise: float = 0.0) -> Dataset:
    """`samples` random vectors labelled by `rule`; the same seed gives the same data set.

    With `noise` > 0 that fraction of the answers, at random, names another task — a
    person clicking through hundreds of vectors is not perfectly consistent either.
    """
    rng = random.Random(seed)
    flips = random.Random(-1 - seed)  # its own stream: the vectors do not depend on the noise
    tasks = len(demand_ranges)
    features: list[list[float]] = []
    labels: list[int] = []
    for _ in range(samples):
        vector = random_levels(rng, demand_ranges)
        label = rule(vector)
        if noise > 0 and flips.random() < noise:
            label = flips.choice([other for other in range(tasks) if other != label])
        features.append([float(value) for value in vector])
        labels.append(label)
    return Dataset(features, labels)
