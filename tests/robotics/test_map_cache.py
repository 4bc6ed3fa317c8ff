"""A map's clearance field and free regions come from this user's cache after the first run: the same
arrays scipy computes, without importing it; a torn cache file is computed again and replaced."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softplc.robotics.gridmap import OccupancyGrid
from softplc.robotics.planner import PathPlanner

REPO = Path(__file__).resolve().parents[2]


def room() -> OccupancyGrid:
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[:, 30] = True  # a wall with a door: two rooms joined
    occupied[18:22, 30] = False
    occupied[5:8, 5:50] = True
    occupied[30:, 40:] = True  # and a closed corner (no door): a region of its own
    occupied[30:, 40] = occupied[30, 40:] = True
    occupied[31:, 41:] = False
    return OccupancyGrid(occupied, 0.05, 0.0, 0.0, "room")


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    return tmp_path / "softplc" / "maps"


def test_the_cached_answers_are_scipys_and_a_torn_file_is_computed_again(cache: Path) -> None:
    from scipy import ndimage

    grid = room()
    first = grid.clearance()
    padded = np.pad(~grid.occupied, 1, constant_values=False)
    assert np.array_equal(first, ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * grid.resolution)
    files = sorted(cache.glob("clearance-*.npy"))
    assert len(files) == 1
    assert np.array_equal(grid.clearance(), first)  # from the file now
    files[0].write_bytes(b"\x93NUMPY torn")
    assert np.array_equal(grid.clearance(), first)  # computed again...
    assert np.array_equal(np.load(files[0]) * grid.resolution, first)  # ...and the file replaced
    planner = PathPlanner(grid, 0.1)
    labels, regions = ndimage.label(~planner.grid.occupied, structure=np.ones((3, 3), dtype=int))
    assert np.array_equal(planner._labels, labels) and regions >= 2  # noqa: SLF001
    assert np.array_equal(PathPlanner(grid, 0.1)._labels, labels)  # noqa: SLF001 - from the cache


def test_a_cache_that_cannot_be_written_is_not_kept_and_nothing_fails(cache: Path) -> None:
    cache.parent.mkdir(parents=True)
    cache.write_text("a file where the directory should be")
    assert room().clearance().shape == (40, 60)


def test_a_second_simulated_run_on_the_same_map_never_imports_scipy(tmp_path: Path) -> None:
    code = ("import sys; from softplc.robotics.gridmap import OccupancyGrid; from softplc.robotics.planner import PathPlanner; "
            "from tests.robotics.test_map_cache import room; g = room(); g.clearance(); PathPlanner(g, 0.1); "
            "print('scipy' in sys.modules)")
    environment = {"XDG_CACHE_HOME": str(tmp_path), "PATH": "/usr/bin:/bin", "PYTHONPATH": str(REPO)}
    runs = [subprocess.run([sys.executable, "-c", code], cwd=REPO, env=environment, capture_output=True, text=True, timeout=60)
            for _ in range(2)]
    assert [run.stdout.strip() for run in runs] == ["True", "False"], [run.stderr[-500:] for run in runs]
