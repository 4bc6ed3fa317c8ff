"""Prometheus metrics of a running plant: `/metrics` on the HMI's web server (docs/operations.md, "Metrics").

Modules, one concept each: `settings` (`servers: hmi: metrics:`, who may scrape), `histograms`
(scan, cycle and start-latency histograms made at scrape time from the tasks' timing windows),
`counters` (writes by source and result, command calls: the core's listeners), `catalog` (the
figures adapters report through their optional `metrics()` method), `collector` (everything read
at scrape time), `adapter` (the route on the HMI's shell, the scrape's access check).

Nothing is done in the scan: a scrape reads what the runtime keeps anyway (task statistics,
program states, the forces) and asks each adapter for its figures; the only per-event work is a
dictionary increment per client write and command call, where the core reports them.
"""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.adapters.metrics.adapter import MetricsAdapter
    from softplc.adapters.metrics.settings import MetricsSettings

# `softplc --help` must not import prometheus_client or aiohttp: names load their module on first use.
_MODULES = {
    "softplc.adapters.metrics.adapter": ("MetricsAdapter",),
    "softplc.adapters.metrics.settings": ("MetricsSettings",),
}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = ["MetricsAdapter", "MetricsSettings"]
