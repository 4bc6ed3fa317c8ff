"""Shared parts of the OPC UA benchmarks: generated plants, `softplc run` in its own process, stats.

The server always runs as `softplc run` (the real command, real time, asyncio loop) in a child
process; the benchmark's asyncua client runs in this process, so both compete for the same
2 cores the way a plant and a SCADA on one small box would.
"""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from softplc.adapters.opcua import Role, UserStore  # noqa: E402

USER, PASSWORD = "bench", "bench-password-1"
logging.getLogger("asyncua").setLevel(logging.ERROR)  # the client's notes on revised parameters are noise here

CHANGER = '''
from softplc import InOut, Output, Param, Program


class Changer(Program):
    """Every scan: count, and give every bound tag a new value (all of them change)."""

    values = Output("tags changed every scan")
    counter = InOut("scan counter")

    def scan(self) -> None:
        self.counter = (self.counter + 1) % 2**31
        self.values = [self.counter] * len(self.values)


class Stamper(Program):
    """Every `every`-th scan: the scan's monotonic time into `stamp` (a sparse change, like the handshake's Ready)."""

    stamp = Output("time.monotonic() of the scan that last changed it, in s")
    every = Param(100, "scans between two changes")

    def setup(self) -> None:
        self.count = 0

    def scan(self) -> None:
        self.count += 1
        if self.count >= self.every:
            self.count = 0
            self.stamp = self.clock.monotonic()
'''


def plant_yaml(tags: int, changing: int, interval: str = "10ms", per_instance: int = 50) -> str:
    """A plant of `tags` tags (folders of `per_instance`), `changing` of them rewritten every scan."""
    instances = max(1, tags // per_instance)
    lines = []
    for index in range(per_instance):
        if index % 3 == 0:
            lines.append(f"      v{index:02d}: {{type: float64, unit: m, min: -1000000, max: 1000000, description: value {index}}}")
        elif index % 3 == 1:
            lines.append(f"      v{index:02d}: {{type: int32, description: value {index}}}")
        else:
            lines.append(f"      v{index:02d}: {{type: bool}}")
    width = max(2, len(str(instances)))
    names = [f"c{i:0{width}d}_v{j:02d}" for i in range(1, instances + 1) for j in range(per_instance) if j % 3 == 1]
    bound = names[:changing]
    if len(bound) < changing:
        raise ValueError(f"only {len(bound)} int32 tags to change")
    binding = "[" + ", ".join(bound) + "]"
    return f"""version: 1
plant: {{name: opcua-bench}}
templates:
  cell:
    group: Cells
    count: {instances}
    prefix: c
    tags:
{chr(10).join(lines)}
tags:
  counter: {{type: int32, access: ro, description: scans of the fast task}}
tasks:
  fast:
    interval: {interval}
    programs:
      - name: changer
        program: bench_changer.py:Changer
        bind: {{values: {binding}, counter: counter}}
"""


def floor_plant_yaml(interval_ms: float, change_every_ms: float = 100.0) -> str:
    """A plant whose only task (at `interval_ms`) stamps `stamp` every `change_every_ms`; `answer`
    and `flag` take a client's writes (the shape of the handshake's answer: a uint16 and a bool)."""
    every = max(1, round(change_every_ms / interval_ms))
    return f"""version: 1
plant: {{name: opcua-floor}}
tags:
  stamp: {{type: float64, unit: s, access: ro, description: monotonic time of the scan that changed it}}
  answer: {{type: uint16, description: written by the client}}
  flag: {{type: bool, description: written by the client}}
tasks:
  fast:
    interval: {interval_ms:g}ms
    programs:
      - name: stamper
        program: bench_changer.py:Stamper
        bind: {{stamp: stamp}}
        params: {{every: {every}}}
"""


def changing_tags(yaml_text: str) -> list[str]:
    match = re.search(r"values: \[([^\]]*)\]", yaml_text)
    return [name.strip() for name in match.group(1).split(",")] if match and match.group(1).strip() else []


@dataclass
class ServerProcess:
    process: subprocess.Popen[str]
    endpoint: str
    ready_seconds: float  # the adapter's own start-up time ("ready in X s")
    launch_to_serving: float  # process launch → "serving:" line (imports and config included)
    folder: Path

    @property
    def pid(self) -> int:
        return self.process.pid

    def rss_mb(self) -> float:
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def cpu_seconds(self) -> float:
        """User + system CPU time the server process has used so far."""
        fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def cpu_wait_seconds(self) -> float:
        """Seconds the server's threads were runnable but waited for a CPU (other processes ran)."""
        total = 0.0
        for task in Path(f"/proc/{self.pid}/task").iterdir():
            try:
                total += int((task / "schedstat").read_text().split()[1]) / 1e9
            except (OSError, IndexError, ValueError):
                pass
        return total

    def stop(self) -> str:
        """Ctrl-C the server; return everything it printed to stderr (incl. task statistics)."""
        self.process.send_signal(signal.SIGINT)
        try:
            _, rest = self.process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            _, rest = self.process.communicate()
        return rest


def start_server(folder: Path, yaml_text: str, *extra: str, opcua: bool = True, nice: int = 0, timeout: float = 120) -> ServerProcess:
    """Write the plant to `folder` and launch `softplc run` on it; wait until it serves.

    `nice` < 0 runs the server at a higher CPU priority than this client and other processes
    (as a PLC runtime is deployed); needs root, else the server runs at normal priority.
    """
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "tagdb.yaml").write_text(yaml_text)
    (folder / "bench_changer.py").write_text(CHANGER)
    UserStore(folder / ".softplc" / "users.yaml").add(USER, Role.OPERATOR, PASSWORD)
    command = [sys.executable, "-m", "softplc.app.cli", "run", str(folder / "tagdb.yaml"), "--no-status", "--no-modbus", "--no-fleet"]
    command += ["--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--opcua-security", "None"] if opcua else ["--no-opcua"]
    command += list(extra)
    if nice:
        command = ["nice", "-n", str(nice), *command]
    launched = time.perf_counter()
    process = subprocess.Popen(command, cwd=str(REPO), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               env=dict(os.environ, PYTHONPATH=str(REPO)))
    endpoint, ready = "", float("nan")
    assert process.stderr is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        if not line:
            raise RuntimeError(f"softplc run exited early (code {process.poll()})")
        found = re.search(r"ready in ([0-9.]+) s", line)
        if found:
            ready = float(found.group(1))
        if line.startswith("serving: OPC UA on "):
            endpoint = line.split()[4]
        if line.startswith("press Ctrl-C"):
            return ServerProcess(process, endpoint, ready, time.perf_counter() - launched, folder)
    process.kill()
    raise RuntimeError("softplc run did not start in time")


def task_latency(stderr: str, task: str = "fast") -> dict[str, float]:
    """The task's start latency min/mean/p99/max (ms) from `softplc run`'s exit statistics."""
    for line in stderr.splitlines():
        columns = line.split()
        if columns and columns[0] == task and len(columns) >= 7:
            minimum, mean, p99, maximum = (float(x) for x in columns[6].split("/"))
            return {"min": minimum, "mean": mean, "p99": p99, "max": maximum, "cycles": float(columns[2]), "overruns": float(columns[3])}
    raise ValueError(f"no statistics for task {task} in:\n{stderr[-2000:]}")


def on_publish(client: Any, subscription: Any, callback: Callable[[Any], None]) -> None:
    """Call `callback(monitored_item_notification)` for every notification as its PublishResponse arrives.

    asyncua's own handler path starts one asyncio task per notification (~30 µs each on the
    client), which at 20k changes/s would measure the client, not the server. This takes the
    decoded PublishResult straight from the client's publish loop instead (a private hook of
    asyncua 2.1.0's client session, acceptable in a benchmark).
    """
    def publish_result(result: Any) -> None:
        for data in result.NotificationMessage.NotificationData or ():
            for item in getattr(data, "MonitoredItems", ()):
                callback(item)

    client.uaclient.session._subscription_callbacks[subscription.subscription_id] = publish_result


def percentile(samples: list[float], fraction: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))] if ordered else float("nan")


def goal(label: str, value: float, limit: float, *, at_least: bool = False) -> bool:
    """Print a goal line; a missed goal is printed LOUDLY."""
    met = value >= limit if at_least else value <= limit
    relation = ">=" if at_least else "<="
    if met:
        print(f"  goal met: {label} = {value:.3g} ({relation} {limit:g})")
    else:
        print(f"\n  !!!!!! GOAL MISSED: {label} = {value:.3g}, goal {relation} {limit:g} !!!!!!\n")
    return met
