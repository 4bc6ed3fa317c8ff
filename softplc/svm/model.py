"""A trained linear SVM task model: train it, save it, load it, predict a task.

Training uses scikit-learn — `SVC(kernel="linear", C=1)` as the thesis did, or `LinearSVC` —
with training accuracy and k-fold cross-validated accuracy. A linear model is fully described
by its weights and intercepts, so it is saved as JSON (portable across scikit-learn versions,
and loading it runs no code, unlike a pickle) with the feature order and the scores; the
fitted estimator is also saved with joblib for use in notebooks.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from softplc.svm.dataset import Dataset, feature_names

ESTIMATORS = ("svc", "linearsvc")


class ModelError(ValueError):
    """A model file that cannot be used; the message says why."""


@dataclass
class TaskModel:
    """Linear decision functions over the features; labels are 0-based task indices."""

    features: list[str]
    classes: list[int]
    coef: list[list[float]]
    intercept: list[float]
    estimator: str = "svc"
    C: float = 1.0
    samples: int = 0
    train_accuracy: float = 0.0
    cv_accuracy: float = 0.0
    cv_folds: int = 0
    class_counts: dict[str, int] = field(default_factory=dict)

    def decision(self, x: list[float]) -> list[float]:
        """w·x + b for each decision function."""
        return [sum(w * v for w, v in zip(row, x)) + b for row, b in zip(self.coef, self.intercept)]

    def predict(self, x: list[float]) -> int:
        """The label (0 → task 1, 1 → task 2, ...) for one feature vector."""
        if len(x) != len(self.features):
            raise ModelError(f"the model takes {len(self.features)} features ({', '.join(self.features)}), got {len(x)}")
        values = self.decision(x)
        if len(self.coef) == 1:  # binary: positive → the second class (scikit-learn's convention)
            return self.classes[1] if values[0] > 0 else self.classes[0]
        return self.classes[max(range(len(values)), key=lambda i: values[i])]  # one-vs-rest

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(asdict(self), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> TaskModel:
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except OSError as error:
            raise ModelError(f"cannot read model {path}: {error.strerror or error}") from None
        except json.JSONDecodeError as error:
            raise ModelError(f"{path} is not a model JSON file: {error}") from None
        try:
            model = cls(**data)
        except TypeError as error:
            raise ModelError(f"{path} is not a softplc SVM model: {error}") from None
        rows = len(model.coef)
        if rows == 0 or any(len(row) != len(model.features) for row in model.coef) or len(model.intercept) != rows:
            raise ModelError(f"{path}: weights do not match its {len(model.features)} features")
        if (rows == 1 and len(model.classes) != 2) or (rows > 1 and rows != len(model.classes)):
            raise ModelError(f"{path}: {rows} decision functions for {len(model.classes)} classes")
        return model


def train(dataset: Dataset, *, C: float = 1.0, estimator: str = "svc", folds: int = 5) -> tuple[TaskModel, Any]:
    """Fit a linear SVM on `dataset`; return the model and the fitted scikit-learn estimator."""
    import numpy as np
    from sklearn.model_selection import StratifiedKFold, cross_val_score
    from sklearn.svm import SVC, LinearSVC

    if estimator not in ESTIMATORS:
        raise ModelError(f"unknown estimator '{estimator}'; choose {' or '.join(ESTIMATORS)}")
    classes = sorted(set(dataset.labels))
    if len(classes) < 2:
        raise ModelError(f"all {len(dataset)} samples have label {classes[0] if classes else '?'}; a model needs two tasks")
    if estimator == "svc" and len(classes) > 2:
        raise ModelError("SVC(kernel='linear') models here take two tasks; use --estimator linearsvc for more")

    def make() -> Any:
        if estimator == "svc":
            return SVC(kernel="linear", C=C)
        return LinearSVC(C=C, max_iter=100_000, random_state=0)

    x = np.asarray(dataset.features, dtype=float)
    y = np.asarray(dataset.labels)
    fitted = make().fit(x, y)
    train_accuracy = float(fitted.score(x, y))
    counts = {str(label): int((y == label).sum()) for label in classes}
    usable_folds = min(folds, min(counts.values()))
    cv_accuracy = 0.0
    if usable_folds >= 2:
        splitter = StratifiedKFold(n_splits=usable_folds)  # unshuffled: the same data gives the same score
        cv_accuracy = float(cross_val_score(make(), x, y, cv=splitter).mean())
    model = TaskModel(
        features=feature_names(dataset.tasks),
        classes=[int(c) for c in fitted.classes_],
        coef=[[float(v) for v in row] for row in fitted.coef_],
        intercept=[float(v) for v in fitted.intercept_],
        estimator=estimator,
        C=C,
        samples=len(dataset),
        train_accuracy=train_accuracy,
        cv_accuracy=cv_accuracy,
        cv_folds=usable_folds if usable_folds >= 2 else 0,
        class_counts=counts,
    )
    return model, fitted


def save_estimator(fitted: Any, path: str | Path) -> None:
    """Save the fitted scikit-learn estimator with joblib (for notebooks; softplc reads the JSON)."""
    import joblib

    joblib.dump(fitted, path)
