"""Occupancy maps (ROS map_server format), the default factory map, and A* on known maps."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO

from softplc.config.yamlsource import ConfigError
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import OccupancyGrid, grid_from_text, load_map, read_pgm
from softplc.robotics.planner import Corridor, Disc, PathPlanner

FACTORY = REPO / "robots" / "maps" / "factory.yaml"
STATIONS = {"t01 source": (3.5, 7.5), "t01 destination": (1.8, 2.5), "t02 source": (18.5, 7.5), "t02 destination": (20.1, 2.4)}
STARTS = {"r01": (7.925, 5.925), "r02": (7.925, 2.925), "r03": (7.925, 4.525)}


def test_factory_map_is_the_thesis_floor() -> None:
    grid = load_map(FACTORY)
    assert (grid.width, grid.height, grid.resolution) == (878, 344, 0.025)
    assert grid.size_m == pytest.approx((21.95, 8.6))
    # Walls all round, obstacles inside (racks, buffers, partitions), mostly free floor.
    assert grid.occupied[0, :].all() and grid.occupied[-1, :].all() and grid.occupied[:, 0].all() and grid.occupied[:, -1].all()
    assert 0.05 < grid.occupied.mean() < 0.25
    assert not grid.is_free(12.5, 4.3)  # the rack island


def test_factory_map_file_is_what_the_script_makes(tmp_path: Path) -> None:
    import runpy

    module = runpy.run_path(str(REPO / "robots" / "maps" / "make_factory_map.py"), run_name="not_main")
    made: OccupancyGrid = module["factory_grid"]()
    assert np.array_equal(made.occupied, load_map(FACTORY).occupied)


@pytest.mark.parametrize("radius", [0.18, 0.39])  # a TurtleBot, and the thesis's largest robot (500 x 600 mm)
def test_every_station_and_start_is_reachable_from_every_other(radius: float) -> None:
    floor = Floor(load_map(FACTORY))
    planner = floor.planner(radius)
    points = [*STATIONS.values(), *STARTS.values()]
    for point in points:
        assert floor.fits(*point, radius), point
        assert planner.is_free(*point), point
    for a in points:
        for b in points:
            if a != b:
                plan = planner.plan(a, b)
                assert plan.ok, (a, b, plan.reason)
                assert plan.path[0] == a and plan.path[-1] == b
                assert plan.length >= math.dist(a, b) - 1e-9


def test_pgm_and_yaml_round_trip_and_map_server_thresholds(tmp_path: Path) -> None:
    grid = grid_from_text("#####\n#...#\n#.#.#\n#####", resolution=0.5, origin=(1.0, 2.0))
    grid.save(tmp_path / "small.yaml")
    loaded = load_map(tmp_path / "small.yaml")
    assert np.array_equal(loaded.occupied, grid.occupied)
    assert (loaded.resolution, loaded.origin_x, loaded.origin_y) == (0.5, 1.0, 2.0)
    assert loaded.is_free(1.0 + 1.25, 2.0 + 1.25) and not loaded.is_free(1.0 + 1.25, 2.0 + 0.75)
    # An ASCII (P2) image with grey levels: 205 is "unknown" (between the thresholds) → not free.
    (tmp_path / "grey.pgm").write_text("P2\n# comment\n3 1\n255\n254 205 0\n")
    (tmp_path / "grey.yaml").write_text("image: grey.pgm\nresolution: 1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "grey.yaml").occupied.tolist() == [[False, True, True]]
    (tmp_path / "negated.yaml").write_text("image: grey.pgm\nresolution: 1\norigin: [0, 0, 0]\nnegate: 1\n")
    assert load_map(tmp_path / "negated.yaml").occupied.tolist() == [[True, True, False]]
    assert read_pgm(tmp_path / "small.pgm").shape == (4, 5)


def test_map_errors_are_located(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text("image: missing.pgm\nresolution: -1\norigin: [0, 0, 0]\n")
    with pytest.raises(ConfigError) as caught:
        load_map(tmp_path / "bad.yaml")
    assert [str(p) for p in caught.value.problems] == [f"{tmp_path / 'bad.yaml'}:2:13: 'resolution' must be more than 0, not -1"]
    (tmp_path / "bad.yaml").write_text("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(ConfigError, match=r"bad.yaml:1:8: cannot read map image .*missing.pgm"):
        load_map(tmp_path / "bad.yaml")
    (tmp_path / "broken.pgm").write_bytes(b"P5\n4 4\n255\n\x00")
    (tmp_path / "bad.yaml").write_text("image: broken.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(ConfigError, match="PGM data is 1 bytes, expected 16"):
        load_map(tmp_path / "bad.yaml")


OPEN = """\
##########
#........#
#........#
#........#
#........#
##########
"""

WALLED = """\
############
#....#.....#
#....#.....#
#....#.....#
############
"""

# Two cells either side of a wall: the only way round is up, across the top and down again.
DETOUR = """\
#########
#.......#
#.#####.#
#.#.#.#.#
#...#...#
#########
"""


def planner_for(text: str) -> PathPlanner:
    # Radius 0 and no margin: the planner works on the grid exactly as drawn (1 m cells).
    return PathPlanner(grid_from_text(text, resolution=1.0), 0.0, resolution=1.0, margin=0.0)


def test_astar_straight_and_diagonal_shortest_lengths() -> None:
    planner = planner_for(OPEN)
    plan = planner.plan((1.5, 1.5), (8.5, 1.5))
    assert plan.ok and plan.grid_length == pytest.approx(7.0) and plan.length == pytest.approx(7.0)
    plan = planner.plan((1.5, 1.5), (8.5, 4.5))
    # 3 diagonal + 4 straight moves on the grid; the smoothed path is the straight line.
    assert plan.grid_length == pytest.approx(3 * math.sqrt(2) + 4)
    assert plan.length == pytest.approx(math.hypot(7, 3))


def test_astar_finds_the_detour() -> None:
    planner = planner_for(DETOUR)
    start, goal = (3.5, 1.5), (5.5, 1.5)
    plan = planner.plan(start, goal)
    assert plan.ok
    # 2 left, 3 up, 6 across, 3 down, 2 left: no diagonal can cut a wall corner.
    assert plan.grid_length == pytest.approx(16.0)
    for (ax, ay), (bx, by) in zip(plan.path, plan.path[1:]):  # every smoothed leg stays in free cells
        for t in np.linspace(0, 1, 50):
            assert planner.grid.is_free(ax + (bx - ax) * t, ay + (by - ay) * t)


def test_unreachable_and_blocked_goals_fail_with_a_reason() -> None:
    planner = planner_for(WALLED)
    plan = planner.plan((1.5, 1.5), (8.5, 2.5))
    assert not plan.ok and "unreachable" in plan.reason and "walls separate them" in plan.reason
    assert plan.expanded == 0  # known at once from the connected regions: no search of the whole map
    plan = planner.plan((1.5, 1.5), (5.5, 2.5))
    assert not plan.ok and "inside an obstacle" in plan.reason
    plan = planner.plan((1.5, 1.5), (40.0, 2.5))
    assert not plan.ok and "outside the map" in plan.reason


def test_other_robots_as_discs_keep_out_routes_and_refuge() -> None:
    planner = planner_for(OPEN)
    # A robot standing in the middle of the room: the path goes around it.
    plan = planner.plan((1.5, 2.5), (8.5, 2.5), discs=[Disc(5.0, 2.5, 1.2)])
    assert plan.ok and plan.grid_length > 7.0
    assert all(math.dist(p, (5.0, 2.5)) > 1.0 for p in plan.path)
    # A wall of robots across the room: no way through.
    plan = planner.plan((1.5, 2.5), (8.5, 2.5), discs=[Disc(5.0, y + 0.5, 0.8) for y in range(1, 5)])
    assert not plan.ok and "other robots" in plan.reason
    # Another robot's route along the room: a refuge is the nearest cell clear of it.
    assert not planner.plan((3.5, 2.5), (8.5, 2.5), keep_out=[Corridor(1.0, 2.5, 9.0, 2.5, 1.2)]).ok
    route = Corridor(1.0, 2.5, 9.0, 2.5, 0.6)
    refuge = planner.refuge((3.5, 2.5), [], [route])
    assert refuge.ok and refuge.path[-1] == (3.5, 4.5)  # the nearest cell clear of it by a cell
    assert not planner.refuge((3.5, 2.5), [], [Corridor(1.0, 2.5, 9.0, 2.5, 3.0)]).ok


def test_inflation_keeps_the_robot_off_walls() -> None:
    grid = load_map(FACTORY)
    planner = Floor(grid).planner(0.18)
    blocked = planner.grid.occupied
    clearance = Floor(grid).clearance
    ys, xs = np.nonzero(~blocked)
    for ix, iy in list(zip(xs, ys))[::97]:  # a sample of free planning cells
        x, y = planner.grid.center(ix, iy)
        assert clearance(x, y) >= 0.18, (x, y)
