"""Global path planning: A* over an occupancy grid inflated by the robot's radius.

Planning runs on a coarser copy of the map (0.1 m by default: the thesis floor is 19k cells
instead of 300k, FIELD-NOTES "Robots and planning"). A plan may add temporary obstacles:
hard discs (another robot's footprint) and soft corridors (where another robot is heading),
which A* avoids when it can and crosses at a cost when it must.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from softplc.robotics.gridmap import OccupancyGrid
from softplc.robotics.map_cache import derived

SQRT2 = math.sqrt(2.0)


def _regions(blocked: np.ndarray) -> np.ndarray:
    """The free cells' 8-connected regions, numbered from 1 (0: blocked)."""
    from scipy import ndimage  # only when the cache has no answer (softplc/robotics/map_cache.py)

    labels, _ = ndimage.label(~blocked, structure=np.ones((3, 3), dtype=int))
    return np.asarray(labels)


@dataclass(frozen=True)
class Disc:
    """A hard circular obstacle (another robot's footprint grown by ours)."""

    x: float
    y: float
    radius: float


@dataclass(frozen=True)
class Corridor:
    """A soft obstacle: the capsule from (x0, y0) to (x1, y1) of half-width `radius`."""

    x0: float
    y0: float
    x1: float
    y1: float
    radius: float
    penalty: float = 8.0  # extra cost per cell entered, in cells


@dataclass
class Plan:
    """The result of planning: a path of world waypoints, or why there is none."""

    ok: bool
    path: list[tuple[float, float]] = field(default_factory=list)
    reason: str = ""
    length: float = 0.0  # metres along the smoothed path
    grid_length: float = 0.0  # metres along the 8-connected A* path, before smoothing
    expanded: int = 0  # cells A* expanded
    seconds: float = 0.0  # wall time spent planning
    refuge: bool = False  # a path off other robots' routes (to make way), not to the goal


class PathPlanner:
    """A* for one robot size on one map (the inflated grid is computed once)."""

    def __init__(
        self,
        grid: OccupancyGrid,
        radius: float,
        *,
        resolution: float = 0.1,
        margin: float = 0.05,
        snap_distance: float = 0.45,
    ) -> None:
        coarse = grid.coarsened(resolution) if resolution > grid.resolution else grid
        self.grid = coarse.inflated(radius + margin)
        self.radius = radius
        self.snap_distance = snap_distance
        self.resolution = self.grid.resolution
        blocked = self.grid.occupied
        # A blocked border of one cell: neighbours never need bounds checks.
        self._padded = np.pad(blocked, 1, constant_values=True)
        self._stride = self._padded.shape[1]
        # A bytearray, not a list: copying it per plan is a memcpy, and the garbage collector
        # never walks it (a 600k-element list made each young-generation pass take ~50 ms).
        self._static = bytearray(self._padded.ravel().astype(np.uint8).tobytes())
        self._labels = derived("regions8", blocked, lambda: _regions(blocked))
        s = self._stride
        # (offset, cost, side a, side b): diagonal moves carry the two orthogonal steps they pass
        # between (no corner cutting); straight ones have no sides (0).
        self._moves = [
            (1, 1.0, 0, 0), (-1, 1.0, 0, 0), (s, 1.0, 0, 0), (-s, 1.0, 0, 0),
            (s + 1, SQRT2, 1, s), (s - 1, SQRT2, -1, s), (-s + 1, SQRT2, 1, -s), (-s - 1, SQRT2, -1, -s),
        ]

    # -- cells ---------------------------------------------------------------------------

    def _index(self, ix: int, iy: int) -> int:
        return (iy + 1) * self._stride + (ix + 1)

    def _cell_of_index(self, index: int) -> tuple[int, int]:
        iy, ix = divmod(index, self._stride)
        return ix - 1, iy - 1

    def is_free(self, x: float, y: float) -> bool:
        """True when a robot centred at (x, y) clears every wall by its radius plus margin."""
        ix, iy = self.grid.cell(x, y)
        return self.grid.inside(ix, iy) and not self.grid.occupied[iy, ix]

    def nearest_free(self, x: float, y: float, within: float, label: int | None = None) -> tuple[int, int] | None:
        """The free cell nearest to (x, y) within `within` metres (optionally in component `label`)."""
        ix, iy = self.grid.cell(x, y)
        reach = int(math.ceil(within / self.resolution)) + 1
        x0, x1 = max(0, ix - reach), min(self.grid.width, ix + reach + 1)
        y0, y1 = max(0, iy - reach), min(self.grid.height, iy + reach + 1)
        if x0 >= x1 or y0 >= y1:
            return None
        window = ~self.grid.occupied[y0:y1, x0:x1]
        if label is not None:
            window &= self._labels[y0:y1, x0:x1] == label
        ys, xs = np.nonzero(window)
        if len(xs) == 0:
            return None
        cx = self.grid.origin_x + (xs + x0 + 0.5) * self.resolution
        cy = self.grid.origin_y + (ys + y0 + 0.5) * self.resolution
        distance = np.hypot(cx - x, cy - y)
        best = int(np.argmin(distance))
        if distance[best] > within + 1e-9:
            return None
        return int(xs[best] + x0), int(ys[best] + y0)

    def component(self, x: float, y: float) -> int:
        """Label of the free region containing (x, y) (0: not in free space)."""
        ix, iy = self.grid.cell(x, y)
        return int(self._labels[iy, ix]) if self.grid.inside(ix, iy) else 0

    # -- planning ------------------------------------------------------------------------

    def plan(
        self,
        start: tuple[float, float],
        goal: tuple[float, float],
        discs: Sequence[Disc] = (),
        corridors: Sequence[Corridor] = (),
        keep_out: Sequence[Corridor] = (),
    ) -> Plan:
        """Shortest collision-free path from `start` to (near) `goal`, or the reason there is none.

        `discs` and `keep_out` capsules are hard obstacles (only the start cell is exempt),
        `corridors` are soft: crossed only when that is cheaper than going around.
        """
        began = time.perf_counter()
        result = self._plan(start, goal, discs, corridors, keep_out)
        result.seconds = time.perf_counter() - began
        return result

    def refuge(self, start: tuple[float, float], discs: Sequence[Disc], keep_out: Sequence[Corridor]) -> Plan:
        """Path to the nearest reachable spot clear of every `keep_out` capsule (to make way)."""
        began = time.perf_counter()
        result = self._refuge(start, discs, keep_out)
        result.seconds = time.perf_counter() - began
        return result

    def _obstacles(self, start: int, goal: int | None, discs: Sequence[Disc], capsules: Sequence[Corridor]) -> bytearray:
        blocked = bytearray(self._static)
        protected = {start, goal}
        for disc in discs:
            for index in self._cells_near(disc.x, disc.y, disc.x, disc.y, disc.radius):
                if index not in protected:
                    blocked[index] = 1
        for capsule in capsules:
            for index in self._cells_near(capsule.x0, capsule.y0, capsule.x1, capsule.y1, capsule.radius):
                if index not in protected:
                    blocked[index] = 1
        return blocked

    def _refuge(self, start: tuple[float, float], discs: Sequence[Disc], keep_out: Sequence[Corridor]) -> Plan:
        start_cell = self.nearest_free(start[0], start[1], 1.0)
        if start_cell is None:
            return Plan(False, reason=f"start ({start[0]:.2f}, {start[1]:.2f}) is not in free space")
        origin = self._index(*start_cell)
        blocked = self._obstacles(origin, None, discs, ())
        unsafe: set[int] = set()
        for capsule in keep_out:
            # One cell more than the capsule: the refuge must be clear of it, not on its rim.
            unsafe.update(self._cells_near(capsule.x0, capsule.y0, capsule.x1, capsule.y1, capsule.radius + self.resolution))
        # Dijkstra outwards; the first settled cell outside every capsule is the nearest refuge.
        cost: dict[int, float] = {origin: 0.0}
        parent: dict[int, int] = {origin: -1}
        heap: list[tuple[float, int]] = [(0.0, origin)]
        settled: set[int] = set()
        while heap:
            distance, current = heapq.heappop(heap)
            if current in settled:
                continue
            settled.add(current)
            if current not in unsafe:
                cells = [current]
                while parent[cells[-1]] != -1:
                    cells.append(parent[cells[-1]])
                cells.reverse()
                cells = self._smooth(cells, blocked, {})
                path = [start] + [self.grid.center(*self._cell_of_index(index)) for index in cells[1:]]
                if len(path) == 1:
                    path.append(start)
                length = sum(math.dist(a, b) for a, b in zip(path, path[1:]))
                return Plan(True, path, length=length, expanded=len(settled))
            for offset, step, side_a, side_b in self._moves:
                neighbour = current + offset
                if blocked[neighbour] or neighbour in settled:
                    continue
                if side_a and (blocked[current + side_a] or blocked[current + side_b]):
                    continue
                new_cost = distance + step
                if new_cost < cost.get(neighbour, math.inf):
                    cost[neighbour] = new_cost
                    parent[neighbour] = current
                    heapq.heappush(heap, (new_cost, neighbour))
        return Plan(False, reason="no spot out of the way is reachable", expanded=len(settled))

    def _plan(
        self,
        start: tuple[float, float],
        goal: tuple[float, float],
        discs: Sequence[Disc],
        corridors: Sequence[Corridor],
        keep_out: Sequence[Corridor] = (),
    ) -> Plan:
        sx, sy = start
        gx, gy = goal
        if not self.grid.inside(*self.grid.cell(gx, gy)):
            return Plan(False, reason=f"goal ({gx:.2f}, {gy:.2f}) is outside the map")
        goal_cell = self.nearest_free(gx, gy, self.snap_distance)
        if goal_cell is None:
            return Plan(False, reason=f"goal ({gx:.2f}, {gy:.2f}) is inside an obstacle or too close to one for a robot of radius {self.radius:.2f} m")
        goal_label = int(self._labels[goal_cell[1], goal_cell[0]])
        start_cell = self.nearest_free(sx, sy, 1.0, goal_label)
        if start_cell is None:
            if self.nearest_free(sx, sy, 1.0) is None:
                return Plan(False, reason=f"start ({sx:.2f}, {sy:.2f}) is not in free space")
            return Plan(False, reason=f"goal ({gx:.2f}, {gy:.2f}) is unreachable from ({sx:.2f}, {sy:.2f}): walls separate them")
        blocked = self._static
        penalty: dict[int, float] = {}
        if discs or keep_out:
            blocked = self._obstacles(self._index(*start_cell), self._index(*goal_cell), discs, keep_out)
        for corridor in corridors:
            for index in self._cells_near(corridor.x0, corridor.y0, corridor.x1, corridor.y1, corridor.radius):
                penalty[index] = max(penalty.get(index, 0.0), corridor.penalty)
        cells, expanded = self._astar(self._index(*start_cell), self._index(*goal_cell), blocked, penalty)
        if cells is None:
            return Plan(False, reason=f"no path to ({gx:.2f}, {gy:.2f}): blocked by other robots", expanded=expanded)
        grid_length = self.resolution * sum(
            1.0 if abs(a - b) in (1, self._stride) else SQRT2 for a, b in zip(cells, cells[1:])
        )
        cells = self._smooth(cells, blocked, penalty)
        path = [(sx, sy)] + [self.grid.center(*self._cell_of_index(index)) for index in cells[1:]]
        if not self.is_free(sx, sy):
            # Starting too close to a wall: first back out to the nearest clear cell.
            path.insert(1, self.grid.center(*start_cell))
        if len(path) == 1:
            path.append(self.grid.center(*goal_cell))
        if self.is_free(gx, gy):
            path[-1] = (gx, gy)  # the goal itself is clear: end exactly there, not at a cell centre
        length = sum(math.dist(a, b) for a, b in zip(path, path[1:]))
        return Plan(True, path, length=length, grid_length=grid_length, expanded=expanded)

    def _cells_near(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> list[int]:
        """Padded indices of cells whose centre is within `radius` of the segment (x0,y0)-(x1,y1)."""
        grid = self.grid
        res = self.resolution
        lo_x, hi_x = min(x0, x1) - radius, max(x0, x1) + radius
        lo_y, hi_y = min(y0, y1) - radius, max(y0, y1) + radius
        ix0, iy0 = grid.cell(lo_x, lo_y)
        ix1, iy1 = grid.cell(hi_x, hi_y)
        ix0, iy0 = max(ix0, 0), max(iy0, 0)
        ix1, iy1 = min(ix1, grid.width - 1), min(iy1, grid.height - 1)
        if ix0 > ix1 or iy0 > iy1:
            return []
        xs = grid.origin_x + (np.arange(ix0, ix1 + 1) + 0.5) * res
        ys = grid.origin_y + (np.arange(iy0, iy1 + 1) + 0.5) * res
        px, py = np.meshgrid(xs, ys)
        dx, dy = x1 - x0, y1 - y0
        length2 = dx * dx + dy * dy
        if length2 > 0:
            t = np.clip(((px - x0) * dx + (py - y0) * dy) / length2, 0.0, 1.0)
        else:
            t = np.zeros_like(px)
        near = np.hypot(px - (x0 + t * dx), py - (y0 + t * dy)) <= radius
        rows, cols = np.nonzero(near)
        return ((rows + iy0 + 1) * self._stride + (cols + ix0 + 1)).tolist()

    def _astar(self, start: int, goal: int, blocked: bytearray, penalty: dict[int, float]) -> tuple[list[int] | None, int]:
        stride = self._stride
        gx, gy = goal % stride, goal // stride
        # Flat lists over the padded grid, not dictionaries: a plan looks each up ~10 times per
        # cell it expands (most of a simulated scenario's time was A*'s dictionary lookups).
        size = len(blocked)
        g_cost = [math.inf] * size
        parent = [-1] * size
        closed = bytearray(size)
        extra = [0.0] * size if penalty else []  # read only when there is a penalty
        for index, cost in penalty.items():
            extra[index] = cost
        moves = self._moves
        g_cost[start] = 0.0
        heap: list[tuple[float, float, int]] = [(0.0, 0.0, start)]
        expanded = 0
        diagonal_extra = SQRT2 - 2.0
        pop, push = heapq.heappop, heapq.heappush
        while heap:
            _, cost, current = pop(heap)
            if closed[current]:
                continue
            if current == goal:
                path = [current]
                while parent[path[-1]] != -1:
                    path.append(parent[path[-1]])
                path.reverse()
                return path, expanded
            closed[current] = 1
            expanded += 1
            for offset, step, side_a, side_b in moves:
                neighbour = current + offset
                if blocked[neighbour] or closed[neighbour]:
                    continue
                if side_a and (blocked[current + side_a] or blocked[current + side_b]):
                    continue
                new_cost = cost + step + extra[neighbour] if penalty else cost + step
                if new_cost < g_cost[neighbour]:
                    g_cost[neighbour] = new_cost
                    parent[neighbour] = current
                    dx = abs(neighbour % stride - gx)
                    dy = abs(neighbour // stride - gy)
                    # Octile distance: admissible and consistent for 8-connected moves.
                    heuristic = dx + dy + diagonal_extra * (dx if dx < dy else dy)
                    push(heap, (new_cost + heuristic, new_cost, neighbour))
        return None, expanded

    def _smooth(self, cells: list[int], blocked: bytearray, penalty: dict[int, float]) -> list[int]:
        """Drop waypoints that a straight line can skip (no obstacle, no penalised cell)."""
        if len(cells) <= 2:
            return cells
        # One array of the cells a line may not touch: each sight line is then a few array
        # operations, not a Python loop over ~3 samples a cell (most of a plan's time before).
        avoid = np.frombuffer(blocked, dtype=np.uint8).astype(bool)
        if penalty:
            avoid[np.fromiter(penalty, dtype=np.intp, count=len(penalty))] = True
        result = [cells[0]]
        anchor = 0
        while anchor < len(cells) - 1:
            reach = anchor + 1
            # Greedy: the farthest waypoint still in sight of the anchor.
            for candidate in range(len(cells) - 1, anchor + 1, -1):
                if self._visible(cells[anchor], cells[candidate], avoid):
                    reach = candidate
                    break
            result.append(cells[reach])
            anchor = reach
        return result

    def _visible(self, a: int, b: int, avoid: np.ndarray) -> bool:
        """Whether the line between the centres of cells `a` and `b` touches no cell of `avoid`."""
        stride = self._stride
        ax, ay = a % stride, a // stride
        bx, by = b % stride, b // stride
        steps = int(max(abs(bx - ax), abs(by - ay)) * 3) + 1
        t = np.arange(steps + 1) / steps
        # Check the cells around each sample point too: the line passes between centres.
        fx, fy = ax + (bx - ax) * t, ay + (by - ay) * t
        columns = (np.floor(fx + 0.49).astype(np.intp), np.floor(fx + 0.51).astype(np.intp))
        rows = (np.floor(fy + 0.49).astype(np.intp) * stride, np.floor(fy + 0.51).astype(np.intp) * stride)
        return not any(avoid[row + column].any() for row in rows for column in columns)
