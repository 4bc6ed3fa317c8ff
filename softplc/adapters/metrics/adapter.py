"""The metrics adapter: the plant's figures in Prometheus's text format, answered to the `metrics.scrape` query.

It counts what the core reports (client writes, command calls) from the plant's start, and at
scrape time reads what the plant keeps anyway (tasks, programs, forces) and each adapter's own
figures (`plant.figures()`). It has no socket of its own: the web HMI serves the query at
`/metrics` to those allowed to scrape (softplc/adapters/hmi/metrics_route.py).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from softplc.adapters.metrics.counters import CommandCounts, WriteCounts
from softplc.core.commands import Permission
from softplc.core.origin import Origin
from softplc.core.plant import Plant

QUERY = "metrics.scrape"


class MetricsAdapter:
    """Adapter: answers `metrics.scrape` with the Prometheus text of this plant."""

    name = "metrics"

    def __init__(self) -> None:
        self.scrapes = 0
        self._registry: Any = None
        self._undo: list[Callable[[], Any]] = []

    async def start(self, plant: Plant) -> None:
        from prometheus_client import CollectorRegistry, GCCollector, PlatformCollector, ProcessCollector

        from softplc.adapters.metrics.collector import PlantCollector

        writes, calls = WriteCounts(), CommandCounts(plant.commands)
        registry = CollectorRegistry()
        registry.register(PlantCollector(plant, writes, calls))
        ProcessCollector(registry=registry)
        PlatformCollector(registry=registry)
        GCCollector(registry=registry)
        self._registry = registry
        self._undo = [
            plant.tags.on_write(writes),
            plant.commands.on_call(calls),
            plant.commands.register(QUERY, self.scrape, permission=Permission.VIEW,
                                    description="read the plant's metrics (Prometheus text format)"),
        ]

    async def stop(self) -> None:
        for undo in reversed(self._undo):
            undo()
        self._undo = []
        self._registry = None

    def scrape(self, arguments: Mapping[str, Any], origin: Origin) -> dict[str, str]:
        """The exposition text and its content type (collecting reads counters the plant keeps: ~1 ms)."""
        from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

        self.scrapes += 1
        return {"content_type": CONTENT_TYPE_LATEST, "text": generate_latest(self._registry).decode()}

    def describe(self) -> str:
        return ""  # the HMI says where /metrics is served
