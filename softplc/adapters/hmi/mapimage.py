"""The factory map as a PNG for the browser: a ROS map_server YAML + PGM, drawn in three shades.

Free floor is light, walls and fixtures dark, unknown space grey (robots never drive there).
The PNG is written with zlib alone (an 8-bit palette image), once per HMI start.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softplc.config.yamlsource import load_yaml

FREE, OCCUPIED, UNKNOWN = (246, 244, 238), (55, 63, 78), (200, 203, 208)


@dataclass(frozen=True)
class MapImage:
    """A map drawn for the page: PNG bytes, and where it lies in the world (metres)."""

    png: bytes
    width_px: int
    height_px: int
    resolution: float  # metres per pixel
    origin_x: float
    origin_y: float

    @property
    def width_m(self) -> float:
        return self.width_px * self.resolution

    @property
    def height_m(self) -> float:
        return self.height_px * self.resolution

    def describe(self) -> dict[str, float]:
        return {"width": self.width_m, "height": self.height_m, "origin_x": self.origin_x, "origin_y": self.origin_y,
                "resolution": self.resolution}


def render_map(yaml_path: Path) -> MapImage:
    """Draw a map_server map (already checked by the fleet's loader) as a palette PNG."""
    from softplc.robotics.gridmap import read_pgm

    data, _ = load_yaml(yaml_path)
    pixels = read_pgm(yaml_path.parent / data["image"]).astype(np.float64) / 255.0
    probability = pixels if data.get("negate", 0) else 1.0 - pixels
    occupied_thresh = float(data.get("occupied_thresh", 0.65))
    free_thresh = float(data.get("free_thresh", 0.196))
    classes = np.full(pixels.shape, 2, dtype=np.uint8)  # unknown
    classes[probability < free_thresh] = 0
    classes[probability > occupied_thresh] = 1
    height, width = classes.shape
    origin = data.get("origin", [0.0, 0.0, 0.0])
    return MapImage(_palette_png(classes, [FREE, OCCUPIED, UNKNOWN]), width, height, float(data["resolution"]),
                    float(origin[0]), float(origin[1]))


def _palette_png(indices: np.ndarray, palette: list[tuple[int, int, int]]) -> bytes:
    """An 8-bit palette PNG of `indices` (row 0 at the top)."""
    height, width = indices.shape
    rows = np.concatenate([np.zeros((height, 1), dtype=np.uint8), indices.astype(np.uint8)], axis=1)  # filter 0 per row

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    return b"".join([
        b"\x89PNG\r\n\x1a\n",
        chunk(b"IHDR", header),
        chunk(b"PLTE", bytes(channel for colour in palette for channel in colour)),
        chunk(b"IDAT", zlib.compress(rows.tobytes(), 9)),
        chunk(b"IEND", b""),
    ])
