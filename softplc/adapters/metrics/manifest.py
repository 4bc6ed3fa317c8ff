"""The metrics adapter's manifest (softplc.config.manifest): its builder."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from softplc.config.manifest import Manifest, flag

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Adapter


def build(config: PlantConfig, args: argparse.Namespace | None) -> list[Adapter]:
    if not served(config, args):
        return []
    from softplc.adapters.metrics.adapter import MetricsAdapter

    return [MetricsAdapter()]


def served(config: PlantConfig, args: argparse.Namespace | None) -> bool:
    """Whether anything serves the figures: the web HMI at /metrics, unless it or its `metrics:` is off.

    Who may scrape is the HMI's to say (servers.hmi.metrics, checked by its section); this only
    reads whether it is on, so nothing is counted for nobody.
    """
    hmi = config.servers.get("hmi")
    hmi = hmi if isinstance(hmi, dict) else {}
    metrics = hmi.get("metrics")
    metrics = metrics if isinstance(metrics, dict) else {}
    return not flag(args, "no_hmi", False) and hmi.get("enabled", True) is not False and metrics.get("enabled", True) is not False


MANIFEST = Manifest(
    name="metrics",
    title="metrics",
    order=70,  # before the HMI, which serves its query at /metrics
    build=build,
    server=True,  # only a server shows it: --no-servers leaves it out
)
