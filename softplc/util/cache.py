"""This user's cache of things softplc computes once per machine: `$XDG_CACHE_HOME/softplc/` (default `~/.cache/softplc/`).

What is kept there can always be computed again: a file that cannot be read is ignored, one that
cannot be written is simply not kept. Files are written aside and renamed, so a reader (another
runtime starting at the same time) never sees half of one.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO


def cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "softplc"


def trusted(status: os.stat_result) -> bool:
    """Owned by this user and writable by nobody else (required of anything that is unpickled)."""
    return status.st_uid == os.getuid() and not status.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def write_atomic(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Make `path` by `write(file)` on a file beside it, renamed over it when complete; raises OSError and write's errors."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    with tempfile.NamedTemporaryFile("wb", dir=path.parent, prefix=path.name, suffix=".tmp", delete=False) as file:
        try:
            write(file)
        except BaseException:
            os.unlink(file.name)
            raise
    os.replace(file.name, path)
