"""Everything `/metrics` shows, read at scrape time (a prometheus_client collector).

Core figures come from what the plant keeps anyway: each task's timing windows and counters
(histograms.py), the programs' states and faults, the plant's state, the forces, and the write
and command counters (counters.py). Each adapter with a `metrics()` method adds its own figures
(`plant.figures()`), named by its manifest. The metric names, types and labels are listed in
docs/operations.md ("Metrics").
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily, Metric
from prometheus_client.registry import Collector

from softplc import __version__
from softplc.adapters.metrics.counters import CommandCounts, WriteCounts
from softplc.adapters.metrics.histograms import LATENCY_BUCKETS, SCAN_BUCKETS, SeriesHistogram, cycle_buckets
from softplc.config.manifest import figure_of
from softplc.core.plant import Plant, TaskView

log = logging.getLogger(__name__)

RUNTIME_STATES = ("STARTING", "RUNNING", "ERROR", "STOPPING", "STOPPED")
PROGRAM_STATES = ("RUNNING", "FAULTED", "STOPPED")


class _TaskFigures:
    """One task's histograms and running counters (monotonic across `_sys.reset_stats`)."""

    def __init__(self, task: TaskView) -> None:
        self.scan = SeriesHistogram(SCAN_BUCKETS)
        self.cycle = SeriesHistogram(cycle_buckets(task.interval))
        self.latency = SeriesHistogram(LATENCY_BUCKETS)
        self.overruns = 0
        self.watchdog_trips = 0
        self._seen = (0, 0)
        self._resets = 0

    def update(self, task: TaskView) -> None:
        stats = task.stats
        for histogram, series in ((self.scan, stats.scan), (self.cycle, stats.cycle), (self.latency, stats.latency)):
            histogram.update(series, stats.resets)
        if stats.resets != self._resets:
            self._resets, self._seen = stats.resets, (0, 0)
        self.overruns += max(0, stats.overruns - self._seen[0])
        self.watchdog_trips += max(0, stats.watchdog_trips - self._seen[1])
        self._seen = (stats.overruns, stats.watchdog_trips)


class PlantCollector(Collector):
    """The plant's metrics, computed when Prometheus asks."""

    def __init__(self, plant: Plant, writes: WriteCounts, calls: CommandCounts) -> None:
        self.plant = plant
        self.writes = writes
        self.calls = calls
        self._tasks: dict[str, _TaskFigures] = {}

    def describe(self) -> list[Metric]:
        return []  # registering must not collect (the runtime may not run yet)

    def collect(self) -> Iterator[Metric]:
        yield from self._runtime()
        yield from self._task_figures()
        yield from self._programs()
        yield from self._counters()
        yield from self._adapters()

    # -- the core ---------------------------------------------------------------------------

    def _runtime(self) -> Iterator[Metric]:
        plant = self.plant
        info = GaugeMetricFamily("softplc_info", "The plant this runtime runs (value 1)", labels=["plant", "version", "simulated"])
        info.add_metric([plant.name, __version__, "true" if plant.clock.simulated else "false"], 1)
        yield info
        state = GaugeMetricFamily("softplc_runtime_state", "The runtime's state (1 for the current one)", labels=["state"])
        for name in RUNTIME_STATES:
            state.add_metric([name], 1 if plant.state == name else 0)
        yield state
        yield GaugeMetricFamily("softplc_tags", "Tags in the tag database", value=len(plant.tags))
        yield GaugeMetricFamily("softplc_forced_tags", "Tags forced by an engineer", value=len(plant.tags.forces))

    def _task_figures(self) -> Iterator[Metric]:
        scan = HistogramMetricFamily("softplc_task_scan_seconds", "Time a task's cycle takes (journal, programs, commit)", labels=["task"])
        cycle = HistogramMetricFamily("softplc_task_cycle_seconds", "Time from one cycle's start to the next (buckets in multiples of the interval)", labels=["task"])
        latency = HistogramMetricFamily("softplc_task_start_latency_seconds", "Delay from a cycle's release to its start", labels=["task"])
        interval = GaugeMetricFamily("softplc_task_interval_seconds", "A task's configured interval", labels=["task"])
        overruns = CounterMetricFamily("softplc_task_overruns", "Releases skipped because a cycle ran past them", labels=["task"])
        trips = CounterMetricFamily("softplc_task_watchdog_trips", "Cycles longer than the task's watchdog", labels=["task"])
        for task in self.plant.tasks:
            figures = self._tasks.get(task.name)
            if figures is None:
                figures = self._tasks[task.name] = _TaskFigures(task)
            figures.update(task)
            for family, histogram in ((scan, figures.scan), (cycle, figures.cycle), (latency, figures.latency)):
                family.add_metric([task.name], histogram.buckets(), histogram.sum)
            interval.add_metric([task.name], task.interval)
            overruns.add_metric([task.name], figures.overruns)
            trips.add_metric([task.name], figures.watchdog_trips)
        yield from (scan, cycle, latency, interval, overruns, trips)

    def _programs(self) -> Iterator[Metric]:
        state = GaugeMetricFamily("softplc_program_state", "A program's state (1 for the current one)", labels=["task", "program", "state"])
        faults = CounterMetricFamily("softplc_program_faults", "Faults of a program since the runtime started", labels=["task", "program"])
        for task in self.plant.tasks:
            for instance in task.programs:
                for name in PROGRAM_STATES:
                    state.add_metric([task.name, instance.name, name], 1 if instance.state.value == name else 0)
                faults.add_metric([task.name, instance.name], instance.faults)
        yield from (state, faults)

    def _counters(self) -> Iterator[Metric]:
        writes = CounterMetricFamily("softplc_writes", "Client writes of tags by source and result (accepted, or the rule a refusal broke)",
                                     labels=["source", "result"])
        for (source, result), count in sorted(self.writes.writes.items()):
            writes.add_metric([source, result], count)
        calls = CounterMetricFamily("softplc_commands", "Calls of commands that act (forcing, program control, alarms...) by result",
                                    labels=["command", "result"])
        for (name, result), count in sorted(self.calls.calls.items()):
            calls.add_metric([name, result], count)
        yield from (writes, calls)

    # -- adapters -------------------------------------------------------------------------

    def _adapters(self) -> Iterator[Metric]:
        families: dict[str, Any] = {}
        for name, figures in self.plant.figures().items():
            for key, value in figures.items():
                self._add(families, name, key, value)
        yield from families.values()

    @staticmethod
    def _add(families: dict[str, Any], adapter: str, key: str, value: Any) -> None:
        labelled = isinstance(value, dict)
        figure = figure_of(adapter, key, labelled)
        family = families.get(figure.name)
        if family is None:
            labels = list(figure.labels) if labelled else []
            kind = CounterMetricFamily if figure.kind == "counter" else GaugeMetricFamily
            family = families[figure.name] = kind(figure.name, figure.help, labels=labels)
        if not labelled:
            family.add_metric([], float(value))
            return
        for label, number in value.items():
            values = [str(part) for part in (label if isinstance(label, tuple) else (label,))]
            family.add_metric(values, float(number))
