"""Occupancy-grid maps in the ROS map_server format: a PGM image plus a YAML description.

    image: factory.pgm         # relative to the YAML file
    resolution: 0.025          # metres per pixel
    origin: [0.0, 0.0, 0.0]    # world pose of the lower-left pixel (x, y, yaw; yaw must be 0)
    negate: 0                  # 1: white is occupied
    occupied_thresh: 0.65      # occupancy probability above which a pixel is occupied
    free_thresh: 0.196         # ... below which it is free (between: unknown, not driven on)

Internally `occupied[iy, ix]` has row 0 at the bottom (y = origin y), so indices grow with x
and y like world coordinates. Unknown pixels count as occupied: a robot never plans into them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from softplc.config import schema_problems
from softplc.config.yamlsource import ConfigError, Location, Problem, load_yaml
from softplc.robotics.map_cache import derived

MAP_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "image": {"type": "string", "description": "PGM file, relative to this YAML file."},
        "resolution": {"type": "number", "exclusiveMinimum": 0, "description": "Metres per pixel."},
        "origin": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
        "negate": {"enum": [0, 1]},
        "occupied_thresh": {"type": "number", "minimum": 0, "maximum": 1},
        "free_thresh": {"type": "number", "minimum": 0, "maximum": 1},
        "mode": {"enum": ["trinary"]},
    },
    "required": ["image", "resolution", "origin"],
    # ROS tools add keys of their own (the thesis's map had obstacle_range, raytrace_range).
    "additionalProperties": True,
}


@dataclass
class OccupancyGrid:
    """A boolean grid of occupied cells with its resolution and world origin."""

    occupied: np.ndarray  # bool [rows (y), cols (x)], row 0 at the bottom
    resolution: float
    origin_x: float = 0.0
    origin_y: float = 0.0
    name: str = "map"

    @property
    def width(self) -> int:
        return int(self.occupied.shape[1])

    @property
    def height(self) -> int:
        return int(self.occupied.shape[0])

    @property
    def size_m(self) -> tuple[float, float]:
        return self.width * self.resolution, self.height * self.resolution

    def cell(self, x: float, y: float) -> tuple[int, int]:
        """(ix, iy) of the cell containing world point (x, y); may lie outside the grid."""
        return (math.floor((x - self.origin_x) / self.resolution), math.floor((y - self.origin_y) / self.resolution))

    def center(self, ix: int, iy: int) -> tuple[float, float]:
        """World coordinates of a cell's centre."""
        return (self.origin_x + (ix + 0.5) * self.resolution, self.origin_y + (iy + 0.5) * self.resolution)

    def inside(self, ix: int, iy: int) -> bool:
        return 0 <= ix < self.width and 0 <= iy < self.height

    def is_free(self, x: float, y: float) -> bool:
        """True when (x, y) lies in a free cell of the map (outside the map is not free)."""
        ix, iy = self.cell(x, y)
        return self.inside(ix, iy) and not self.occupied[iy, ix]

    def clearance(self) -> np.ndarray:
        """Distance (m) from each cell centre to the nearest occupied cell (or the map edge)."""
        # Pad with an occupied border so the map's edge counts as a wall.
        def compute() -> np.ndarray:
            from scipy import ndimage  # only when the cache has no answer (softplc/robotics/map_cache.py)

            padded = np.pad(~self.occupied, 1, constant_values=False)
            return np.asarray(ndimage.distance_transform_edt(padded)[1:-1, 1:-1], dtype=np.float64)

        return derived("clearance", self.occupied, compute) * self.resolution

    def inflated(self, radius: float) -> OccupancyGrid:
        """A grid where every cell closer than `radius` (m) to an obstacle is occupied too."""
        blocked = self.clearance() < radius + 1e-9 if radius > 0 else self.occupied.copy()
        return OccupancyGrid(blocked | self.occupied, self.resolution, self.origin_x, self.origin_y, self.name)

    def coarsened(self, resolution: float) -> OccupancyGrid:
        """The map at a coarser resolution: a coarse cell is occupied if any fine cell in it is."""
        factor = max(1, round(resolution / self.resolution))
        if factor == 1:
            return self
        rows = -(-self.height // factor) * factor
        cols = -(-self.width // factor) * factor
        padded = np.ones((rows, cols), dtype=bool)
        padded[: self.height, : self.width] = self.occupied
        blocks = padded.reshape(rows // factor, factor, cols // factor, factor).any(axis=(1, 3))
        return OccupancyGrid(blocks, self.resolution * factor, self.origin_x, self.origin_y, self.name)

    # -- files ---------------------------------------------------------------------------

    def save(self, yaml_path: str | Path, *, occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> None:
        """Write `NAME.yaml` + `NAME.pgm` (binary P5, free = 254, occupied = 0)."""
        yaml_path = Path(yaml_path)
        image_path = yaml_path.with_suffix(".pgm")
        pixels = np.where(self.occupied[::-1], 0, 254).astype(np.uint8)  # image row 0 is the top
        header = f"P5\n# softplc occupancy grid {self.name}\n{self.width} {self.height}\n255\n".encode()
        image_path.write_bytes(header + pixels.tobytes())
        yaml_path.write_text(
            f"image: {image_path.name}\n"
            f"resolution: {self.resolution:g}\n"
            f"origin: [{self.origin_x:g}, {self.origin_y:g}, 0.0]\n"
            "negate: 0\n"
            f"occupied_thresh: {occupied_thresh:g}\n"
            f"free_thresh: {free_thresh:g}\n"
        )


def load_map(yaml_path: str | Path) -> OccupancyGrid:
    """Load a map_server YAML + PGM; raise ConfigError with FILE:LINE:COL on mistakes."""
    yaml_path = Path(yaml_path)
    data, source = load_yaml(yaml_path)
    if not isinstance(data, dict):
        raise ConfigError([source.problem((), "a map file must be a mapping (image, resolution, origin, ...)")])
    problems = schema_problems(data, source, MAP_SCHEMA)
    if problems:
        raise ConfigError(problems)
    if data["origin"][2] != 0:
        raise ConfigError([source.problem(("origin", 2), "rotated maps are not supported: the origin yaw must be 0")])
    occupied_thresh = float(data.get("occupied_thresh", 0.65))
    free_thresh = float(data.get("free_thresh", 0.196))
    if free_thresh > occupied_thresh:
        raise ConfigError([source.problem(("free_thresh",), f"free_thresh {free_thresh} is above occupied_thresh {occupied_thresh}")])
    image_path = yaml_path.parent / data["image"]
    try:
        pixels = read_pgm(image_path)
    except (OSError, ValueError) as error:
        raise ConfigError([source.problem(("image",), f"cannot read map image {image_path}: {error}")]) from None
    # map_server: p = (255 - value) / 255 (or value / 255 with negate), then thresholds.
    scaled = pixels.astype(np.float64) / 255.0
    probability = scaled if data.get("negate", 0) else 1.0 - scaled
    free = probability < free_thresh
    return OccupancyGrid(~free[::-1].copy(), float(data["resolution"]), float(data["origin"][0]), float(data["origin"][1]), yaml_path.stem)


def read_pgm(path: str | Path) -> np.ndarray:
    """Pixels of a binary (P5) or ASCII (P2) 8-bit PGM image, row 0 at the top."""
    raw = Path(path).read_bytes()
    tokens: list[bytes] = []
    position = 0
    # Header: magic, width, height, maxval — separated by whitespace, with # comments.
    while len(tokens) < 4:
        while position < len(raw) and raw[position : position + 1].isspace():
            position += 1
        if raw[position : position + 1] == b"#":
            position = raw.index(b"\n", position) + 1
            continue
        end = position
        while end < len(raw) and not raw[end : end + 1].isspace():
            end += 1
        if end == position:
            raise ValueError("truncated PGM header")
        tokens.append(raw[position:end])
        position = end
    magic, width, height, maxval = tokens[0], int(tokens[1]), int(tokens[2]), int(tokens[3])
    if maxval <= 0 or maxval > 255:
        raise ValueError(f"only 8-bit PGM images are supported (maxval {maxval})")
    if magic == b"P5":
        data = raw[position + 1 : position + 1 + width * height]
        if len(data) != width * height:
            raise ValueError(f"PGM data is {len(data)} bytes, expected {width * height}")
        pixels = np.frombuffer(data, dtype=np.uint8).reshape(height, width)
    elif magic == b"P2":
        values = raw[position:].split()
        if len(values) < width * height:
            raise ValueError(f"PGM has {len(values)} values, expected {width * height}")
        pixels = np.array([int(v) for v in values[: width * height]], dtype=np.uint8).reshape(height, width)
    else:
        raise ValueError(f"not a PGM image (magic {magic!r}; expected P5 or P2)")
    if maxval != 255:
        pixels = (pixels.astype(np.uint16) * 255 // maxval).astype(np.uint8)
    return pixels


def grid_from_text(text: str, resolution: float = 1.0, origin: tuple[float, float] = (0.0, 0.0)) -> OccupancyGrid:
    """A small grid drawn as text ('#' occupied, anything else free; first line is the top)."""
    lines = [line for line in text.strip("\n").splitlines()]
    width = max(len(line) for line in lines)
    rows = [[ch == "#" for ch in line.ljust(width)] for line in lines]
    return OccupancyGrid(np.array(rows[::-1], dtype=bool), resolution, origin[0], origin[1], "text")


def map_problem(path: str | Path, message: str) -> ConfigError:
    """A ConfigError pointing at a map file as a whole."""
    return ConfigError([Problem(Location(str(path), 1, 1), message)])
