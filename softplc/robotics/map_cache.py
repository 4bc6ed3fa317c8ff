"""What is derived from a map once per machine — its clearance field, its free regions — kept in this user's cache.

Both come from scipy.ndimage (a Euclidean distance transform, a labelling of connected cells),
whose import alone takes ~0.25 s: a quarter of the start of a simulated run of the default
plant. The arrays depend only on the grid and the question, so they are kept in
`~/.cache/softplc/maps/` (softplc/util/cache.py) under a SHA-256 of both, as plain `.npy` files
(loaded without pickle); a later run on the same map loads them and never imports scipy. A file
that cannot be read is computed again; a cache that cannot be written is not kept.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Callable

import numpy as np

from softplc.util.cache import cache_dir, write_atomic

log = logging.getLogger(__name__)


def derived(kind: str, grid: np.ndarray, compute: Callable[[], np.ndarray]) -> np.ndarray:
    """`compute()` for this `kind` of question about `grid` (a boolean array), from the cache when it was asked before."""
    digest = hashlib.sha256(f"{kind}|{grid.shape}|{grid.dtype}|".encode() + np.packbits(grid).tobytes()).hexdigest()
    path = cache_dir() / "maps" / f"{kind}-{digest[:32]}.npy"
    try:
        found = np.load(path, allow_pickle=False)
        if found.shape == grid.shape:
            return found
    except FileNotFoundError:
        pass
    except (OSError, ValueError) as error:  # torn or foreign: computed again, and replaced
        log.info("map cache: ignoring %s (%s)", path, error)
    result = compute()
    try:
        write_atomic(path, lambda file: np.save(file, result, allow_pickle=False))
    except OSError as error:
        log.info("map cache: could not keep %s: %s", path, error)
    return result
