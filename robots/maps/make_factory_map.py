"""Generate the default factory map: the thesis's simulated floor, 21.95 m x 8.6 m at 0.025 m/px.

    .venv/bin/python robots/maps/make_factory_map.py      # writes factory.pgm + factory.yaml here

Layout (metres; stations are where a robot stands, SPEC §2):

    y=8.6 +----------------------------------------------------------------------------+
          |      [T1 input buffer]                              [T2 input buffer]      |
          |        T1 src (3.5,7.5)                               T2 src (18.5,7.5)    |
          |                        |                                      |            |
          |            #           |  r01 (7.925,5.925) +---------+       |      #     |
          |   (pillar 2.6,5.0)     |  r03 (7.925,4.525) |  racks  |       |  (pillar)  |
          |[T1 out]                   r02 (7.925,2.925) +---------+                    |
          |[store] T1 dest (1.8,2.5)                                T2 dest (20.1,2.4)[T2 out]|
    y=0   +----------------------------------------------------------------------------+
          x=0                                                                       x=21.95

A rack island (x 10-15, y 3.4-5.2) splits the middle into an upper and a lower aisle (3.2 m
wide); two partitions separate the task areas with passages above and below them. Every
aisle is at least 2.4 m wide, so two of the thesis's largest robots (500 x 600 mm) can pass.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

from softplc.robotics.gridmap import OccupancyGrid  # noqa: E402

WIDTH_M, HEIGHT_M, RESOLUTION = 21.95, 8.6, 0.025
WALL = 0.1

# (x0, y0, x1, y1) in metres: everything that is not floor.
OBSTACLES: list[tuple[float, float, float, float]] = [
    (2.7, 8.15, 4.3, 8.6),  # task 1 input buffer (conveyor), north of its source station
    (0.0, 1.7, 1.15, 3.3),  # task 1 output storage, west of its destination station
    (17.7, 8.15, 19.3, 8.6),  # task 2 input buffer
    (20.75, 1.6, 21.95, 3.2),  # task 2 output storage, east of its destination station
    (10.0, 3.4, 15.0, 5.2),  # rack island in the middle of the floor
    (5.4, 3.6, 5.6, 6.0),  # partition between the task 1 area and the robot parking
    (16.8, 2.8, 17.0, 5.8),  # partition in front of the task 2 area
    (2.4, 4.8, 2.8, 5.2),  # building pillars
    (19.3, 4.8, 19.7, 5.2),
]

STATIONS = {"t01 source": (3.5, 7.5), "t01 destination": (1.8, 2.5), "t02 source": (18.5, 7.5), "t02 destination": (20.1, 2.4)}
STARTS = {"r01": (7.925, 5.925), "r02": (7.925, 2.925), "r03": (7.925, 4.525)}


def factory_grid() -> OccupancyGrid:
    """The factory floor as an occupancy grid (row 0 at y = 0)."""
    cols, rows = round(WIDTH_M / RESOLUTION), round(HEIGHT_M / RESOLUTION)
    occupied = np.zeros((rows, cols), dtype=bool)
    wall = round(WALL / RESOLUTION)
    occupied[:wall, :] = occupied[-wall:, :] = True
    occupied[:, :wall] = occupied[:, -wall:] = True
    for x0, y0, x1, y1 in OBSTACLES:
        occupied[round(y0 / RESOLUTION) : round(y1 / RESOLUTION), round(x0 / RESOLUTION) : round(x1 / RESOLUTION)] = True
    return OccupancyGrid(occupied, RESOLUTION, 0.0, 0.0, "factory")


def main() -> None:
    grid = factory_grid()
    # The thesis's map YAML (Appendix D2) used occupied_thresh 0.3 and free_thresh 0.2.
    grid.save(HERE / "factory.yaml", occupied_thresh=0.3, free_thresh=0.2)
    print(f"wrote {HERE / 'factory.pgm'} ({grid.width} x {grid.height} px) and factory.yaml")


if __name__ == "__main__":
    main()
