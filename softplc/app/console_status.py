"""What `softplc run` says on the terminal while it runs: what it serves, a live status line, the tasks' figures at the end."""

from __future__ import annotations

import argparse
import asyncio
import sys
from typing import Any, TextIO

from softplc.util.console import print_table
from softplc.util.durations import format_duration
from softplc.util.plurals import plural


async def status_loop(runtime: Any, show: bool, args: argparse.Namespace) -> None:
    """Announce the adapters once they are up, then keep a one-line status (real time)."""
    await runtime.running.wait()
    for adapter in runtime.adapters:
        for line in filter(None, adapter.describe().splitlines()):  # an adapter may serve in several places, or say nothing
            print(f"serving: {line}", file=sys.stderr)
    if not runtime.adapters:
        print("serving: nothing (no server enabled)", file=sys.stderr)
    from softplc.app.adapters import servers_off

    for note in servers_off(runtime.config, args):
        print(f"not serving: {note}", file=sys.stderr)
    print("press Ctrl-C to stop", file=sys.stderr)
    last_error = ""
    while True:
        await asyncio.sleep(0.5 if show else 1.0)
        if runtime.error and runtime.error != last_error:
            last_error = runtime.error
            print(f"\nsoftplc: {runtime.state.value}: {runtime.error}", file=sys.stderr)
        if show:
            print("\r" + status_line(runtime) + "\033[K", end="", file=sys.stderr, flush=True)


def status_line(runtime: Any) -> str:
    parts = [f"{runtime.state.value}", f"t={runtime.clock.now():9.1f}s"]
    for task in runtime.tasks:
        stats = task.stats
        parts.append(f"{task.name}: {plural(stats.cycles, 'cycle')}, {plural(stats.overruns, 'overrun')}")
    faulted = [i.name for t in runtime.tasks for i in t.programs if i.state.value == "FAULTED"]
    if faulted:
        parts.append("FAULTED: " + ", ".join(faulted))
    return " | ".join(parts)


def print_task_statistics(runtime: Any, stream: TextIO) -> None:
    header = ("task", "interval", "cycles", "overruns", "wd trips", "scan ms min/mean/p99/max", "latency ms min/mean/p99/max", "cycle ms mean/max")
    rows = []
    for task in runtime.tasks:
        stats = task.stats
        scan, latency, cycle = stats.scan.summary(), stats.latency.summary(), stats.cycle.summary()
        rows.append([
            task.name,
            format_duration(task.interval),
            str(stats.cycles),
            str(stats.overruns),
            str(stats.watchdog_trips),
            "/".join(f"{scan[k]:.3f}" for k in ("min", "mean", "p99", "max")),
            "/".join(f"{latency[k]:.3f}" for k in ("min", "mean", "p99", "max")),
            "/".join(f"{cycle[k]:.3f}" for k in ("mean", "max")),
        ])
    if rows:
        print_table(rows, header, stream)
    for task in runtime.tasks:
        for instance in task.programs:
            if instance.state.value != "RUNNING":
                print(f"program {instance.name}: {instance.state.value} {instance.error}", file=stream)
