"""What adapters report for `/metrics`, through one small optional method each:

    def metrics(self) -> dict[str, Any]:
        '''Figures for /metrics (softplc/adapters/metrics/catalog.py): name → number, or name → {label value(s): number}.'''
        return {"sessions": 2, "requests": {("3", "ok"): 1500, ("16", "exception"): 2}}

The adapter names its figures; this catalog gives each (adapter, figure) its metric name, type,
help text and label names, so adapters stay free of prometheus_client and the names are defined
in one place (docs/operations.md lists them). A figure the catalog does not know is still shown,
as a gauge `softplc_ADAPTER_FIGURE` (label `key` for a mapping). `metrics()` runs on the event
loop at scrape time: it reads counters the adapter keeps anyway and must be cheap.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Figure:
    """How one adapter figure is shown: metric name, gauge or counter, help, label names (for a mapping)."""

    name: str
    kind: str  # "gauge" or "counter" (a counter's name ends in _total)
    help: str
    labels: tuple[str, ...] = ()


def _gauge(name: str, help: str, *labels: str) -> Figure:
    return Figure(name, "gauge", help, labels)


def _counter(name: str, help: str, *labels: str) -> Figure:
    return Figure(name, "counter", help, labels)


CATALOG: dict[tuple[str, str], Figure] = {
    ("opcua", "sessions"): _gauge("softplc_opcua_sessions", "OPC UA sessions open (activated)"),
    ("opcua", "subscriptions"): _gauge("softplc_opcua_subscriptions", "OPC UA subscriptions"),
    ("opcua", "monitored_items"): _gauge("softplc_opcua_monitored_items", "OPC UA monitored items of every subscription"),
    ("modbus", "connections"): _gauge("softplc_modbus_connections", "Modbus TCP client connections open"),
    ("modbus", "connections_refused"): _counter("softplc_modbus_connections_refused_total", "Modbus TCP connections refused (max_connections)"),
    ("modbus", "connections_closed"): _counter("softplc_modbus_connections_closed_total", "Modbus TCP connections the server closed, by reason (idle, framing)", "reason"),
    ("modbus", "requests"): _counter("softplc_modbus_requests_total", "Modbus TCP requests answered, by function code and result (ok, exception)", "function", "result"),
    ("hmi", "clients"): _gauge("softplc_hmi_clients", "HMI live connections (browser tabs) open"),
    ("hmi", "sessions"): _gauge("softplc_hmi_sessions", "HMI login sessions"),
    ("hmi", "clients_dropped"): _counter("softplc_hmi_clients_dropped_total", "HMI live clients dropped for being too slow or silent"),
    ("hmi", "updates_encoded"): _counter("softplc_hmi_updates_encoded_total", "HMI live messages encoded (each sent to every client of its group)"),
    ("fleet", "robots"): _gauge("softplc_robots", "Robots by navigation state (offline: a remote robot not reporting)", "navstate"),
    ("history", "tags"): _gauge("softplc_history_tags", "Tags the historian records"),
    ("history", "rows_written"): _counter("softplc_history_rows_written_total", "History rows committed to the store"),
    ("history", "queue"): _gauge("softplc_history_queue_rows", "History rows waiting for the writer (the queue depth)"),
    ("history", "rows_dropped"): _counter("softplc_history_rows_dropped_total", "History rows dropped because the queue was full (the store was down)"),
    ("history", "errors"): _counter("softplc_history_write_errors_total", "Failed history commits (retried)"),
    ("alarms", "active"): _gauge("softplc_alarms_active", "Alarms active (unacknowledged or acknowledged), not shelved or suppressed"),
    ("alarms", "unacknowledged"): _gauge("softplc_alarms_unacknowledged", "Alarms waiting for an acknowledgement"),
    ("alarms", "shelved"): _gauge("softplc_alarms_shelved", "Alarms shelved"),
}


def figure_of(adapter: str, key: str, labelled: bool) -> Figure:
    """The catalog's entry, or a gauge named after the adapter and the figure."""
    known = CATALOG.get((adapter, key))
    if known is not None:
        return known
    name = re.sub(r"[^a-zA-Z0-9_]", "_", f"softplc_{adapter}_{key}")
    return _gauge(name, f"{key} (reported by the {adapter} adapter)", *(("key",) if labelled else ()))
