"""Shared fixtures: build a plant from a YAML string, run it on the simulated clock."""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

from softplc.config import PlantConfig, load_config

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def make_config(tmp_path: Path) -> Callable[[str], PlantConfig]:
    """Write YAML text to tmp_path/tagdb.yaml and load it (programs/ resolves from the repo)."""

    def make(text: str, name: str = "tagdb.yaml") -> PlantConfig:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return load_config(path)

    return make
