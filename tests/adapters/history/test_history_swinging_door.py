"""Swinging-door compression and the exception deadband, against hand-computed vectors."""

from __future__ import annotations

import math

from softplc.adapters.history.columns import QUALITY_CODES
from softplc.adapters.history.recorder import TagFilter
from softplc.adapters.history.settings import TagPolicy
from softplc.adapters.history.swinging_door import SwingingDoor
from softplc.core.tags import Quality


def archive(door: SwingingDoor, points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    stored: list[tuple[float, float]] = []
    for when, value in points:
        stored += door.offer(when, value)
    return stored


def test_a_ramp_then_a_jump_keeps_the_ramp_ends_only() -> None:
    # deviation 1, hinge (0, 0). Doors after each point (upper, lower slope):
    # (1, .5): (1.5, -0.5); (2, 1): (1, 0); (3, 1.5): (.833, .167);
    # (4, 5): lower = (5-1-0)/4 = 1 > upper .833 → archive the held (3, 1.5), hold (4, 5).
    door = SwingingDoor(1.0)
    assert archive(door, [(0, 0), (1, 0.5), (2, 1.0), (3, 1.5), (4, 5.0)]) == [(0, 0), (3, 1.5)]
    assert door.held == (4, 5.0)
    assert door.release() == [(4, 5.0)]


def test_noise_inside_the_deviation_is_not_stored() -> None:
    # Noise of ±0.2 around 10, deviation 0.5, hinge (0, 9.8): the upper door's slopes are
    # (9.8+0.5-9.8)/t = 0.5/t > 0 and the lower door's (10.2-0.5-9.8)/t = -0.1/t < 0: never closed.
    door = SwingingDoor(0.5)
    noisy = [(t, 10 + (0.2 if t % 2 else -0.2)) for t in range(0, 50)]
    assert archive(door, noisy) == [(0, 9.8)]
    assert door.held == (49, 10.2)
    # Noise of ±0.4 (0.8 peak to peak) does not fit: hinge (0, 9.6), then (1, 10.4) gives the
    # doors (1.3, 0.3), and (2, 9.6) the upper slope (9.6+0.5-9.6)/2 = 0.25 < 0.3: (1, 10.4) is archived.
    door = SwingingDoor(0.5)
    assert archive(door, [(0, 9.6), (1, 10.4), (2, 9.6)]) == [(0, 9.6), (1, 10.4)]


def test_every_value_read_back_by_interpolation_is_within_twice_the_deviation() -> None:
    # Every value lies within the deviation of one line from the hinge through the doors; the
    # line to the archived point departs from it by less than the deviation again.
    deviation = 0.05
    door = SwingingDoor(deviation)
    signal = [(t / 10, math.sin(t / 10)) for t in range(0, 400)]
    stored = archive(door, signal) + door.release()
    assert len(stored) < len(signal) / 5  # it does compress
    errors: list[float] = []
    for when, value in signal:
        after = next(i for i, point in enumerate(stored) if point[0] >= when)
        (t0, v0), (t1, v1) = stored[max(after - 1, 0)], stored[after]
        read_back = v1 if t1 == t0 else v0 + (v1 - v0) * (when - t0) / (t1 - t0)
        assert abs(read_back - value) <= 2 * deviation + 1e-9, when
        errors.append(abs(read_back - value))
    assert sum(errors) / len(errors) < deviation


def test_max_interval_archives_a_slow_drift_and_min_interval_spaces_points() -> None:
    # A flat value with max_interval 5: the held value is archived once 5 s passed since the hinge.
    door = SwingingDoor(1.0, max_interval=5.0)
    assert archive(door, [(t, 3.0) for t in range(0, 12)]) == [(0, 3.0), (5, 3.0), (10, 3.0)]
    # A zigzag of ±2 would archive every point; min_interval 3 keeps them 3 s apart at least.
    door = SwingingDoor(0.5, min_interval=3.0)
    zigzag = [(t, 2.0 if t % 2 else -2.0) for t in range(0, 10)]
    stored = archive(door, zigzag)
    assert stored[0] == (0, -2.0)
    assert all(b[0] - a[0] >= 3.0 for a, b in zip(stored, stored[1:])), stored
    assert door.due(100.0) is False  # no max_interval: never due


def test_deadband_compares_with_the_last_recorded_value_not_the_previous_sample() -> None:
    tag = TagFilter("x", TagPolicy(deadband=1.0), numeric=True)
    values = [0.0, 0.6, 1.2, 1.5, 2.1, 2.3, 0.9]
    stored = [row[2] for when, value in enumerate(values) for row in tag.offer(float(when), value, Quality.GOOD)]
    # 0 stored; 0.6, 1.2? |1.2-0| > 1 → stored; 1.5, 2.1 within 1 of 1.2 (2.1-1.2 = .9); 2.3 → stored; 0.9 → stored.
    assert stored == [0.0, 1.2, 2.3, 0.9]


def test_a_quality_change_is_recorded_with_the_held_value_first() -> None:
    tag = TagFilter("x", TagPolicy(compression=(1.0, 0.0, math.inf)), numeric=True)
    rows = []
    for when, value, quality in [(0, 0.0, Quality.GOOD), (1, 0.1, Quality.GOOD), (2, 0.2, Quality.GOOD),
                                 (3, 0.2, Quality.BAD), (4, 0.2, Quality.BAD), (5, 7.0, Quality.GOOD)]:
        rows += tag.offer(float(when), value, quality)
    good, bad = QUALITY_CODES[Quality.GOOD], QUALITY_CODES[Quality.BAD]
    assert [(r[1], r[2], r[3]) for r in rows] == [
        (0, 0.0, good),
        (2, 0.2, good),  # the held value, released by the change of quality
        (3, 0.2, bad),
        (4, 0.2, bad),  # a bad value is not compressed
        (5, 7.0, good),
    ]


def test_strings_and_booleans_are_recorded_on_every_change() -> None:
    tag = TagFilter("s", TagPolicy(stepped=True), numeric=False)
    rows = [row for when, value in enumerate(["idle", "moving", "idle"]) for row in tag.offer(float(when), value, Quality.GOOD)]
    assert [row[2] for row in rows] == ["idle", "moving", "idle"]
