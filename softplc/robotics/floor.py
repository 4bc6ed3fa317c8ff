"""The floor a fleet drives on: the map, its clearance, and one planner per robot size."""

from __future__ import annotations

import math
import threading

import numpy as np

from softplc.robotics.gridmap import OccupancyGrid
from softplc.robotics.planner import PathPlanner


class Floor:
    """A map shared by all robots: wall clearance for safety checks and cached planners."""

    def __init__(self, grid: OccupancyGrid, *, planning_resolution: float = 0.1, margin: float = 0.15) -> None:
        self.grid = grid
        self.planning_resolution = planning_resolution
        self.margin = margin
        # Distance from every fine cell to the nearest wall: the ground truth for "is this
        # robot touching a wall", independent of the coarse planning grid.
        # Distances are between cell centres: the wall's surface is half a cell nearer, and a
        # point is up to half a cell diagonal from its cell's centre, so subtract both.
        self._clearance = (grid.clearance() - 1.21 * grid.resolution).astype(np.float32)
        self._planners: dict[int, PathPlanner] = {}
        self._lock = threading.Lock()  # planners may be requested from executor threads

    def clearance(self, x: float, y: float) -> float:
        """Metres from (x, y) to the nearest wall, never overestimated (<= 0: touching or outside)."""
        ix, iy = self.grid.cell(x, y)
        if not self.grid.inside(ix, iy):
            return 0.0
        return float(self._clearance[iy, ix])

    def fits(self, x: float, y: float, radius: float) -> bool:
        """True when a robot of `radius` centred at (x, y) touches no wall."""
        return self.clearance(x, y) >= radius

    def planner(self, radius: float) -> PathPlanner:
        """The planner for robots of this radius (built once, rounded to the centimetre)."""
        key = int(math.ceil(radius * 100))
        with self._lock:
            planner = self._planners.get(key)
            if planner is None:
                planner = PathPlanner(self.grid, key / 100.0, resolution=self.planning_resolution, margin=self.margin)
                self._planners[key] = planner
            return planner
