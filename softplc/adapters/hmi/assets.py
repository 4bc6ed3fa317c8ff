"""Where the HMI's front-end files (the top-level `hmi/` folder) are, in a clone and once installed.

A clone (or an editable install) serves `hmi/` next to the `softplc` package, so an edited page
shows on reload. `pip install .` copies the folder into the environment's data directory
(`share/softplc/hmi`, the `data-files` of pyproject.toml), where an installed runtime finds it.
`SOFTPLC_HMI_DIR` points elsewhere (a customised front-end).
"""

from __future__ import annotations

import os
import sys
import sysconfig
from pathlib import Path

MARKER = "softplc-hmi.txt"  # a file only our front-end folder has (another "hmi" folder is not ours)


class AssetsNotFound(FileNotFoundError):
    """No front-end folder was found: the message says where we looked."""


def candidates() -> list[Path]:
    """Folders that may hold the front-end, in the order they are tried."""
    found = []
    override = os.environ.get("SOFTPLC_HMI_DIR")
    if override:
        found.append(Path(override))
    found.append(Path(__file__).resolve().parents[3] / "hmi")  # a clone: <repo>/softplc/adapters/hmi/assets.py
    for prefix in dict.fromkeys([sysconfig.get_path("data"), sys.prefix, sys.base_prefix]):
        found.append(Path(prefix) / "share" / "softplc" / "hmi")
    return found


def find_assets(folders: list[Path] | None = None) -> Path:
    """The first folder holding the HMI front-end."""
    folders = candidates() if folders is None else folders
    for folder in folders:
        if (folder / MARKER).is_file() and (folder / "index.html").is_file():
            return folder
    tried = ", ".join(str(folder) for folder in folders)
    raise AssetsNotFound(f"the HMI's web files are missing (looked in {tried}); reinstall softplc or set SOFTPLC_HMI_DIR")
