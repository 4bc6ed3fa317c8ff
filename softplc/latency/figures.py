"""PNG figures like thesis Figures 5.17–5.19: delay over time with mean and std, and its distribution."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # made directly, not through pyplot: files only, no backend or display

from softplc.latency.report import hires_delays, plc_delays
from softplc.latency.results import Measurement
from softplc.latency.statistics import DelayStatistics, summarize


def figure_name(run: Measurement) -> str:
    return f"latency-{run.target.protocol}-{run.target.scenario}-{run.target.scan * 1000.0:g}ms.png"


def write_figure(run: Measurement, directory: Path) -> Path:
    """One PNG per run: the PLC's delay (top) and the high-resolution delay (bottom)."""
    plc = plc_delays(run)
    hires = hires_delays(run)
    rows = [("PLC delay, scan-quantised", plc, run.target.scan * 1000.0)]
    if hires:
        rows.append(("Ready → TaskID acknowledged, high resolution", hires, None))
    figure = Figure(figsize=(12, 3.6 * len(rows)))
    axes = figure.subplots(len(rows), 2, squeeze=False, gridspec_kw={"width_ratios": [2.2, 1]})
    for (title, values, category), (over_time, distribution) in zip(rows, axes):
        stats = summarize(values)
        _over_time(over_time, values, stats, title)
        _distribution(distribution, values, stats, category)
    mode = run.target.mode
    figure.suptitle(f"Case study IV handshake — {run.target.protocol} ({mode}), {run.target.scenario} scenario, "
                    f"scan {run.target.scan * 1000.0:g} ms, {len(run.ok_samples)} samples", fontsize=11)
    figure.tight_layout()
    path = directory / figure_name(run)
    figure.savefig(path, dpi=110)
    return path


def _over_time(axis: Axes, values: list[float], stats: DelayStatistics, title: str) -> None:
    axis.set_title(title, fontsize=10)
    axis.set_xlabel("sample")
    axis.set_ylabel("delay (ms)")
    if not values:
        axis.text(0.5, 0.5, "no samples", ha="center", va="center", transform=axis.transAxes)
        return
    axis.plot(np.arange(1, len(values) + 1), values, linewidth=0.6, marker=".", markersize=2, color="tab:blue", label="delay")
    assert stats.mean is not None
    axis.axhline(stats.mean, color="tab:green", linewidth=1.2, label=f"mean {stats.mean:.2f} ms")
    if stats.std is not None:
        axis.axhline(stats.mean + stats.std, color="tab:orange", linewidth=1.0, linestyle="--",
                     label=f"mean + std {stats.mean + stats.std:.2f} ms")
    axis.set_ylim(0, max(values) * 1.25)  # room for the legend above the highest sample
    axis.legend(loc="upper right", fontsize=8)
    axis.grid(alpha=0.3)


def _distribution(axis: Axes, values: list[float], stats: DelayStatistics, category: float | None) -> None:
    axis.set_title("frequency distribution", fontsize=10)
    axis.set_xlabel("delay (ms)")
    axis.set_ylabel("% of samples")
    if not values:
        return
    if category:
        # Thesis style: one bar per scan multiple (10 ms, 20 ms, ...).
        scans = np.round(np.asarray(values) / category).astype(int)
        labels, counts = np.unique(scans, return_counts=True)
        percent = 100.0 * counts / len(values)
        positions = np.arange(len(labels))
        axis.bar(positions, percent, color="tab:blue")
        axis.set_xticks(positions, [f"{label * category:g}" for label in labels])
        for index, value in enumerate(percent):
            axis.text(index, value, f"{value:.1f}", ha="center", va="bottom", fontsize=8)
    else:
        histogram = stats.histogram
        assert histogram is not None
        percent = 100.0 * np.asarray(histogram.counts) / len(values)
        axis.bar(histogram.edges[:-1], percent, width=histogram.width, align="edge", color="tab:blue")
    axis.grid(alpha=0.3, axis="y")
