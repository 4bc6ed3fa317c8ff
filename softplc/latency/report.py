"""The latency report: Table-8-style text beside the thesis's figures, JSON statistics, CSV samples.

Two delays per handshake (see docs/latency.md):
- PLC (scan): what the PLC program measured, quantised to its scan — the thesis's figure;
- hi-res: Ready set in the PLC → the client's TaskID write acknowledged, from monotonic
  timestamps of both processes (same machine only) — the protocol's share, without the wait
  for the next scan.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from softplc.latency.results import Measurement, Sample
from softplc.latency.statistics import DelayStatistics, share_at_most, summarize
from softplc.util.plurals import plural

# Thesis Table 8: Beckhoff TwinCAT soft-PLC + its OPC server + a Python OPC client, 10 ms scan.
THESIS_TABLE_8: dict[str, dict[str, float]] = {
    "slow": {"mean": 21.5, "std": 10.6, "mean_plus_std": 32.1, "samples": 150, "worst": 60, "share_le_20": 70, "share_20_40": 28, "share_gt_40": 2},
    "average": {"mean": 15.6, "std": 14.0, "mean_plus_std": 29.6, "samples": 294, "worst": 220, "share_le_20": 95, "share_20_40": 3, "share_gt_40": 2},
    "fast": {"mean": 15.8, "std": 10.8, "mean_plus_std": 26.6, "samples": 1117, "worst": 120, "share_le_20": 92, "share_20_40": 5, "share_gt_40": 3},
}
THESIS_SCAN_MS = 10.0

ROWS: tuple[tuple[str, str, bool], ...] = (
    # (label, field, ratio shown)
    ("Mean (ms)", "mean", True),
    ("Std. deviation (ms)", "std", True),
    ("Mean + std (ms)", "mean_plus_std", True),
    ("Total no. of samples", "samples", False),
    ("Worst delay (ms)", "worst", True),
    ("≤ 20 ms (%)", "share_le_20", True),
    ("> 20 and ≤ 40 ms (%)", "share_20_40", True),
    ("> 40 ms (%)", "share_gt_40", True),
)
# The number of samples behind each share (the thesis's are its rounded shares of its samples).
SHARE_COUNTS = {"share_le_20": "count_le_20", "share_20_40": "count_20_40", "share_gt_40": "count_gt_40"}
MODES = {"none": "None", "sign": "Sign", "signandencrypt": "SignAndEncrypt"}


def security_mode(measurement: Measurement) -> str | None:
    """The OPC UA security mode of a run (None, Sign, SignAndEncrypt); None for Modbus."""
    target = measurement.target
    if target.protocol != "opcua":
        return None
    if not target.security:
        return "None"
    first = target.security.split(",")[0].strip()
    return MODES.get(first.lower().removeprefix("basic256sha256_"), first)


def plc_delays(measurement: Measurement) -> list[float]:
    return [s.plc_delay_ms for s in measurement.ok_samples if s.plc_delay_ms is not None]


def hires_delays(measurement: Measurement) -> list[float]:
    values = [s.hires_ms(measurement.same_clock) for s in measurement.ok_samples]
    return [v for v in values if v is not None]


def notify_delays(measurement: Measurement) -> list[float]:
    values = [s.notify_ms(measurement.same_clock) for s in measurement.ok_samples]
    return [v for v in values if v is not None]


def respond_delays(measurement: Measurement) -> list[float]:
    return [s.respond_ms() for s in measurement.ok_samples]


def one_scan_share(measurement: Measurement) -> float | None:
    """Percent of samples the PLC saw the answer at the very next scan (the floor)."""
    scans = [s.plc_delay_scans for s in measurement.ok_samples if s.plc_delay_scans is not None]
    if scans:
        return 100.0 * sum(1 for n in scans if n <= 1) / len(scans)
    return share_at_most(plc_delays(measurement), measurement.target.scan * 1000.0 * 1.5)


def statistics(measurement: Measurement) -> dict[str, DelayStatistics]:
    scan_ms = measurement.target.scan * 1000.0
    return {
        "plc": summarize(plc_delays(measurement), bin_width=scan_ms if measurement.target.endpoint is None else None),
        "hires": summarize(hires_delays(measurement)),
        "notify": summarize(notify_delays(measurement)),
        "respond": summarize(respond_delays(measurement)),
    }


def to_json(measurement: Measurement) -> dict[str, Any]:
    """The statistics of one run, as printed by --json and written by --out."""
    target = measurement.target
    stats = statistics(measurement)
    thesis = THESIS_TABLE_8[target.scenario]
    plc = stats["plc"]
    ratios = {key: _ratio(getattr(plc, key), thesis[key]) for _, key, shown in ROWS if shown}
    return {
        "label": measurement.label or _short(measurement),
        "protocol": target.protocol,
        "scenario": target.scenario,
        "scan_ms": target.scan * 1000.0,
        "client": target.mode,
        "security": security_mode(measurement),
        "endpoint": measurement.endpoint,
        "local_runtime": target.endpoint is None,
        "same_clock": measurement.same_clock,
        "driver": measurement.driver,
        "requested": {"samples": target.samples, "duration_s": target.duration},
        "samples": len(measurement.ok_samples),
        "warmup": len(measurement.warmup),
        "timeouts": measurement.timeouts,
        "missed": measurement.missed,
        "missed_notes": measurement.missed_notes,
        "not_attempted": measurement.not_attempted,
        "connected": measurement.connected,
        "ended": measurement.ended,
        "unreported": measurement.unreported,
        "foreign": measurement.foreign,
        "stamps_lost": measurement.stamps_lost,
        "errors": measurement.errors,
        "complete": measurement.complete,
        "client_exit": measurement.client_exit,
        "wall_seconds": round(measurement.wall_seconds, 3),
        "one_scan_percent": one_scan_share(measurement),
        "plc": plc.to_dict(),
        "hires": stats["hires"].to_dict(),
        "notify": stats["notify"].to_dict(),
        "respond": stats["respond"].to_dict(),
        "thesis": thesis,
        "ratio_to_thesis": ratios,
        "plc_task": measurement.plc_task,
        "conditions": measurement.conditions,
    }


def _ratio(ours: float | None, theirs: float) -> float | None:
    if ours is None or not theirs:
        return None
    return ours / theirs


def _cell(value: Any, digits: int = 1) -> str:
    if value is None:
        return "–"
    if isinstance(value, float) and math.isnan(value):
        return "–"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}f}"


def print_report(measurements: Sequence[Measurement], out: TextIO) -> None:
    """Table 8 per scenario (ours beside the thesis), then each run's details."""
    scenarios = list(dict.fromkeys(m.target.scenario for m in measurements))
    for scenario in scenarios:
        runs = [m for m in measurements if m.target.scenario == scenario]
        if any(run.ok_samples for run in runs):  # a table of dashes tells nothing
            _print_table(scenario, runs, out)
        for run in runs:
            _print_details(run, out)
        print(file=out)


def _print_table(scenario: str, runs: Sequence[Measurement], out: TextIO) -> None:
    thesis = THESIS_TABLE_8[scenario]
    scans = sorted({m.target.scan * 1000.0 for m in runs})
    scan_text = "/".join(f"{s:g}" for s in scans)
    title = f"Handshake latency, case study IV — {scenario} scenario, PLC scan {scan_text} ms (thesis: {THESIS_SCAN_MS:g} ms)"
    modes = {_short(run): security_mode(run) for run in runs if security_mode(run) is not None}
    if len(set(modes.values())) == 1:
        title += f"; OPC UA security {next(iter(modes.values()))}"
    elif modes:
        title += "; OPC UA security " + ", ".join(f"{name}: {mode}" for name, mode in modes.items())
    print(title, file=out)
    header = ["", "thesis"]
    columns: list[list[str]] = []
    for run in runs:
        stats = statistics(run)
        name = _short(run)
        header += [f"{name} PLC", "×thesis", f"{name} hi-res"]
        plc, hires = stats["plc"], stats["hires"]
        plc_column, ratio_column, hires_column = [], [], []
        for _, key, shown in ROWS:
            plc_column.append(_stat_cell(plc, key, 1))
            ratio = _ratio(getattr(plc, key), thesis[key]) if shown else None
            ratio_column.append(f"{ratio:.2f}" if ratio is not None else "")
            hires_column.append(_stat_cell(hires, key, 2))
        columns += [plc_column, ratio_column, hires_column]
    rows = []
    for index, (label, key, _) in enumerate(ROWS):
        thesis_value = thesis[key]
        thesis_cell = f"{thesis_value:g}"
        if key in SHARE_COUNTS:
            thesis_cell += f" (≈{round(thesis_value * thesis['samples'] / 100):d})"
        row = [label, thesis_cell]
        row += [column[index] for column in columns]
        rows.append(row)
    _table(rows, header, out)
    print("shares: % (number of samples); ×thesis: ours / the thesis's, for a share our % / its % (few samples say little)", file=out)


def _stat_cell(stats: DelayStatistics, key: str, digits: int) -> str:
    if key == "samples":
        return str(stats.samples)
    cell = _cell(getattr(stats, key), digits)
    if key in SHARE_COUNTS and stats.samples:
        cell += f" ({getattr(stats, SHARE_COUNTS[key])})"
    return cell


def outcome(run: Measurement) -> str:
    """Requested, measured, missed, not attempted, and why the run ended."""
    target = run.target
    if target.duration is not None:
        requested = f"requested {target.duration:g} s"
    else:
        requested = f"requested {plural(target.samples or 0, 'sample')}"
    parts = [requested, f"measured {len(run.ok_samples)}", f"missed {run.missed}"]
    if run.not_attempted is not None:
        parts.append(f"not attempted {run.not_attempted}")
    return " · ".join(parts) + f" · run ended: {run.ended or ('complete' if run.complete else 'error')}"


def _short(run: Measurement) -> str:
    if run.label:
        return run.label
    name = {"opcua": "OPC UA", "modbus": "Modbus"}[run.target.protocol]
    if run.target.protocol == "opcua":
        name += " sub" if run.target.mode == "subscription" else " poll"
    scans = run.target.scan * 1000.0
    return f"{name} {scans:g}ms"


def _print_details(run: Measurement, out: TextIO) -> None:
    stats = statistics(run)
    target = run.target
    print(f"\n{_short(run)} — {run.driver or run.endpoint}", file=out)
    where = "our runtime (real time)" if target.endpoint is None else f"--endpoint {run.endpoint}"
    warmup = f" (+{plural(len(run.warmup), 'warm-up answer')}, not counted)" if run.warmup else ""
    print(f"  PLC: {where}; {plural(len(run.ok_samples), 'sample')} in {run.wall_seconds:.0f} s{warmup}", file=out)
    print(f"  {outcome(run)}", file=out)
    for note in run.missed_notes:
        print(f"  missed: {note}", file=out)
    share = one_scan_share(run)
    if share is not None:
        print(f"  seen at the next scan (the floor): {share:.2f} % of samples", file=out)
    for key, title in (("plc", "PLC (scan)"), ("hires", "hi-res Ready→TaskID acked"), ("notify", "  of which Ready→client saw it"), ("respond", "  of which client saw→write acked")):
        s = stats[key]
        if not s.samples:
            if key == "hires" and not run.same_clock:
                print(f"  {title}: not available (the PLC is on another machine: its monotonic clock is not ours)", file=out)
            continue
        p = s.percentiles
        print(f"  {title:32s} mean {s.mean:7.3f}  p50 {p['p50']:7.3f}  p95 {p['p95']:7.3f}  p99 {p['p99']:7.3f}  "
              f"p99.9 {p['p999']:7.3f}  worst {s.worst:7.3f} ms", file=out)
    counters = f"timeouts {run.timeouts} · missed {run.missed} · unreported {run.unreported}"
    if run.foreign:
        counters += f" · switches by another client {run.foreign}"
    if run.stamps_lost:
        counters += f" · no hi-res delay for {run.stamps_lost} (the PLC's next Ready overwrote ReadyStamp before the client read it)"
    if "unexpected_taskids" in run.plc_task:
        # programs/handshake.py: TaskIDs written while a task ran; Readys cleared without a new TaskID.
        counters += f" · PLC's Unexpected {run.plc_task['unexpected_taskids']} · BadAnswers {run.plc_task.get('ready_raised_again', 0)}"
    print(f"  {counters}", file=out)
    for error in run.errors:
        print(f"  ERROR: {error}", file=out)
    histogram = stats["hires"].histogram if stats["hires"].samples else stats["plc"].histogram
    if histogram is not None:
        label = "hi-res" if stats["hires"].samples else "PLC"
        print(f"  {label} histogram ({histogram.width:g} ms bins):", file=out)
        total = sum(histogram.counts) or 1
        # Empty bins are left out: the tail shows as a few lines, not pages of zeros.
        for label_text, count in histogram.rows():
            if count:
                bar = "#" * max(1, round(40 * count / total))
                print(f"    {label_text:>13s} ms {count:6d} {100.0 * count / total:6.2f} % {bar}", file=out)
    if run.plc_task:
        latency = run.plc_task["start_latency_ms"]
        print(f"  PLC task: {plural(run.plc_task['cycles'], 'cycle')}, {plural(run.plc_task['overruns'], 'overrun')}, start latency mean "
              f"{latency['mean']:.3f} / p99 {latency['p99']:.3f} / max {latency['max']:.3f} ms", file=out)
    c = run.conditions
    cpu = ""
    if "cpu_busy_percent" in c:
        cpu = f", CPUs {c['cpu_busy_percent']:g} % busy and {c['cpu_steal_percent']:g} % stolen by the hypervisor during the run"
    placement = ""
    if c.get("client_cpus"):
        placement = f", runtime on CPU {c.get('runtime_cpus')} and client on CPU {c['client_cpus']}"
    print(f"  conditions: {c.get('cpus')} CPUs, load average {c.get('load_average_1_5_15')} at start{cpu}, "
          f"Python {c.get('python')}, {c.get('event_loop')} loop{placement}", file=out)


def _table(rows: list[list[str]], header: list[str], out: TextIO) -> None:
    widths = [max([len(h)] + [len(row[i]) for row in rows]) for i, h in enumerate(header)]
    print("  ".join(h.rjust(w) if i else h.ljust(w) for i, (h, w) in enumerate(zip(header, widths))).rstrip(), file=out)
    print("  ".join("-" * w for w in widths), file=out)
    for row in rows:
        print("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths))).rstrip(), file=out)


CSV_FIELDS = ("label", "protocol", "scenario", "scan_ms", "kind", "index", "task_id", "status", "ready_stamp", "t_seen", "t_sent", "t_done",
              "plc_delay_ms", "plc_delay_scans", "plc_handshakes", "hires_ms", "notify_ms", "respond_ms")


def write_csv(measurements: Sequence[Measurement], path: Path) -> None:
    """Every sample (and warm-up answer) of every run, one row each."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_FIELDS)
        for run in measurements:
            for kind, samples in (("warmup", run.warmup), ("sample", run.samples)):
                for sample in samples:
                    writer.writerow(_csv_row(run, kind, sample))


def _csv_row(run: Measurement, kind: str, sample: Sample) -> list[Any]:
    def fmt(value: float | None, digits: int) -> str:
        return "" if value is None else f"{value:.{digits}f}"

    return [run.label or _short(run), run.target.protocol, run.target.scenario, f"{run.target.scan * 1000.0:g}", kind, sample.index, sample.task_id, sample.status,
            fmt(sample.ready_stamp, 6), fmt(sample.t_seen, 6), fmt(sample.t_sent, 6), fmt(sample.t_done, 6),
            fmt(sample.plc_delay_ms, 3), "" if sample.plc_delay_scans is None else sample.plc_delay_scans,
            "" if sample.plc_handshakes is None else sample.plc_handshakes,
            fmt(sample.hires_ms(run.same_clock), 4), fmt(sample.notify_ms(run.same_clock), 4), fmt(sample.respond_ms(), 4)]
