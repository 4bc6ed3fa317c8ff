"""What a robot sees of the others: the nearest robots, the same with or without the grid of a large fleet."""

from __future__ import annotations

import math
import random

import pytest

from softplc.robotics import peers as peers_module
from softplc.robotics.peers import GRID_FROM, SMALL_FLEET, PeerView


def _fleet(count: int, seed: int) -> PeerView:
    rng = random.Random(seed)
    ids = [f"r{index:04d}" for index in range(count)]
    rows = [[rng.uniform(0, 40), rng.uniform(0, 25), rng.uniform(-3, 3), rng.uniform(0, 0.3),
             rng.choice(["idle", "moving", "blocked", "arrived"]), 0.2, "", ""] for _ in ids]
    for row in rows[:20]:  # robots stacked on one spot and on a cell's border: ties and edges
        row[0], row[1] = 4.0, 6.0
    for row in rows[20:30]:
        row[0], row[1] = 10.0 + rng.choice([-1e-12, 0.0, 1e-12]), 2.0
    rows[30][0] = math.nan
    rows[31][1] = math.inf
    return PeerView(ids, rows)


def _small_fleet(count: int, seed: int) -> PeerView:
    rng = random.Random(seed)
    ids = [f"r{index:02d}" for index in range(count)]
    rows = [[rng.uniform(0, 6), rng.uniform(0, 4), 0.0, 0.0, "moving", 0.2, "", ""] for _ in ids]
    rows[1][0], rows[1][1] = rows[2][0], rows[2][1] = 3.0, 2.0  # a tie
    rows[-1][0] = math.nan
    if count > 4:
        rows[-2][1] = math.inf
    return PeerView(ids, rows)


def _brute(view: PeerView, robot_id: str, x: float, y: float, within: float) -> list[str]:
    """The definition: every other robot within reach, nearest first, ties by position."""
    found = []
    for position, other in enumerate(view.ids):
        distance = math.hypot(view.x[position] - x, view.y[position] - y)
        if other != robot_id and distance <= within:
            found.append((distance, position, other))
    return [other for _, _, other in sorted(found)]


@pytest.mark.parametrize("seed", range(3))
def test_a_large_fleet_finds_the_same_neighbours_through_the_grid(seed: int) -> None:
    view = _fleet(GRID_FROM * 8, seed)
    rng = random.Random(seed + 100)
    queries = [(view.ids[rng.randrange(len(view.ids))], rng.uniform(-2, 42), rng.uniform(-2, 27), rng.choice([0.0, 0.5, 2.0, 3.0, 5.5]))
               for _ in range(400)]
    queries += [(view.ids[0], 4.0, 6.0, 0.0), (view.ids[0], 10.0, 2.0, 1e-9), (view.ids[5], 0.0, 0.0, math.inf),
                (view.ids[5], math.nan, 1.0, 3.0), (view.ids[5], 1.0, 1.0, -1.0), (view.ids[5], 1.0, 1.0, 1e12)]
    for robot_id, x, y, within in queries:
        got = [peer.id for peer in view.near(robot_id, x, y, within)]
        assert got == _brute(view, robot_id, x, y, within), (robot_id, x, y, within)


def test_moving_robots_are_found_where_they_are_now() -> None:
    view = _fleet(GRID_FROM * 2, 7)
    assert "r0100" not in [peer.id for peer in view.near("r0000", 39.0, 24.0, 0.5)]
    view.update(100, "xpos", 39.1)
    view.update(100, "ypos", 24.1)
    found = view.near("r0000", 39.0, 24.0, 0.5)
    assert "r0100" in [peer.id for peer in found]
    peer = next(peer for peer in found if peer.id == "r0100")
    assert (peer.x, peer.y) == (39.1, 24.1)
    view.update(100, "navstate", "moving")
    assert next(peer for peer in view.near("r0000", 39.0, 24.0, 0.5) if peer.id == "r0100").active


def test_a_small_fleet_needs_no_grid(monkeypatch: pytest.MonkeyPatch) -> None:
    view = _fleet(GRID_FROM - 1, 3)
    monkeypatch.setattr(PeerView, "_within_cells", lambda *args: pytest.fail("a small fleet looked in the grid"))
    assert [peer.id for peer in view.near("r0000", 4.0, 6.0, 3.0)] == _brute(view, "r0000", 4.0, 6.0, 3.0)
    assert peers_module.GRID_FROM == GRID_FROM


@pytest.mark.parametrize("count", [3, SMALL_FLEET - 1, SMALL_FLEET, GRID_FROM - 1])
def test_fleets_of_every_size_find_the_neighbours_the_definition_finds(count: int) -> None:
    view = _small_fleet(count, count)
    rng = random.Random(count)
    queries = [(view.ids[rng.randrange(count)], rng.uniform(-1, 7), rng.uniform(-1, 5), rng.choice([0.0, 0.5, 2.0, 3.0]))
               for _ in range(200)]
    queries += [(view.ids[0], 3.0, 2.0, 0.0), (view.ids[0], 3.0, 2.0, math.inf), (view.ids[0], math.nan, 1.0, 3.0),
                (view.ids[1], 1.0, 1.0, -1.0), ("nobody", 3.0, 2.0, 1.0)]
    for robot_id, x, y, within in queries:
        got = [peer.id for peer in view.near(robot_id, x, y, within)]
        assert got == _brute(view, robot_id, x, y, within), (robot_id, x, y, within)
