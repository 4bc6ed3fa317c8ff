"""TimingSeries.percentile gives exactly np.percentile's (linear) value, faster."""

import random

import numpy as np
import pytest

from softplc.core.stats import TimingSeries


@pytest.mark.parametrize("count", [1, 2, 3, 10, 101, 9_999, 10_000, 12_345])
def test_percentile_equals_numpy(count):
    rng = random.Random(count)
    series = TimingSeries()
    values = [rng.random() * rng.choice([1e-4, 1e-2, 1.0]) for _ in range(count)]
    for value in values:
        series.add(value)
    window = np.array(values[-10_000:])
    for q in (0, 1, 50, 99, 99.9, 100):
        assert series.percentile(q) == float(np.percentile(window, q))


def test_percentile_of_nothing_is_zero():
    assert TimingSeries().percentile(99) == 0.0


def test_a_series_of_one_value_has_that_value_as_every_percentile() -> None:
    series = TimingSeries(window=100)
    for _ in range(250):
        series.add(0.1)
    assert series.percentile(99) == series.percentile(1) == 0.1 == float(np.percentile(series.recent(100), 99))
    series.add(0.2)
    assert series.percentile(100) == 0.2 and series.percentile(0) == 0.1
    series.reset()
    series.add(0.0)
    assert series.summary() == {"min": 0.0, "max": 0.0, "mean": 0.0, "p99": 0.0}
