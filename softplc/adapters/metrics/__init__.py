"""Prometheus metrics of a running plant, answered to the `metrics.scrape` query (docs/operations.md, "Metrics").

Modules, one concept each: `histograms` (scan, cycle and start-latency histograms made at scrape
time from the tasks' timing windows), `counters` (writes by source and result, command calls:
the core's listeners), `collector` (everything read at scrape time), `adapter` (the query),
`manifest` (how the runtime finds it). The web HMI serves the query at `/metrics` and decides who
may scrape (softplc/adapters/hmi/metrics_route.py).

Nothing is done in the scan: a scrape reads what the plant keeps anyway (task statistics,
program states, the forces) and asks each adapter for its figures; the only per-event work is a
dictionary increment per client write and command call, where the core reports them.
"""
