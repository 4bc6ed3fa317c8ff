"""Sparkplug B edge node: metric changes/s published batched, the 10 ms task's start latency meanwhile, rebirth time.

An in-process runtime on the real clock (no servers) runs `probe`, a small program every 10 ms
at the highest priority (its start latency is what is measured), and `flood`, a program that
changes --tags float tags at every scan of its own --interval; the Sparkplug B edge node
publishes them (--devices devices by tag pattern, aliases) to a mosquitto on a free loopback
port. A subscriber in another process counts the metrics it receives in DDATA messages.
Then --rebirths times: an NCMD `Node Control/Rebirth`, and the time until the NBIRTH and until
the last DBIRTH arrive (a listener on this process's loop, subscribed to the births only).

Goals (issue 26): >= 50,000 metric changes/s published batched with the 10 ms task's p99 start
latency <= 1 ms; rebirth <= 1 s after the NCMD.

    .venv/bin/python bench/sparkplug_throughput.py                  # 600 tags x 10 ms = 60,000/s offered, 5 devices
    .venv/bin/python bench/sparkplug_throughput.py --baseline       # the same plant without the edge node
    .venv/bin/python bench/sparkplug_throughput.py --tags 5000 --interval 100ms
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.flood_plant import flood_plant, tag_names  # noqa: E402
from bench.timing import load_average  # noqa: E402

GOAL_RATE = 50_000
GOAL_P99_MS = 1.0
GOAL_REBIRTH_S = 1.0


def plant(tags: int, interval: str, devices: int, port: int, sparkplug: bool) -> str:
    names = tag_names(tags)
    per_device = -(-tags // devices)
    device_list = "\n".join(f"    - {{id: d{number}, tags: [{', '.join(names[number * per_device:(number + 1) * per_device])}]}}"
                            for number in range(devices))
    section = f"""
mqtt: {{url: "mqtt://127.0.0.1:{port}"}}
sparkplug:
  group_id: bench
  edge_node_id: node
  store: {{enabled: false}}
  devices:
{device_list}
""" if sparkplug else ""
    return flood_plant("sparkplug-bench", tags, interval, section)


SUBSCRIBER = """
import asyncio, json, sys
sys.path.insert(0, sys.argv[2])
from softplc.core.clock import RealClock
from softplc.protocols.mqtt import MqttConnection
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.protocols.sparkplug import sparkplug_b_pb2 as pb

async def main():
    counts = {"messages": 0, "metrics": 0}
    def count(topic, payload, retained):
        counts["messages"] += 1
        counts["metrics"] += len(pb.Payload.FromString(payload).metrics)
    connection = MqttConnection(MqttSettings(port=int(sys.argv[1])), "bench-subscriber", RealClock())
    connection.subscribe("spBv1.0/bench/DDATA/#", count)
    task = asyncio.create_task(connection.run())
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    print(json.dumps({"ready": True}), flush=True)
    while line := await reader.readline():
        print(json.dumps(counts), flush=True)
    task.cancel()

asyncio.run(main())
"""


class Subscriber:
    """The counting subscriber in its own process: `counts()` asks it for what it received so far."""

    def __init__(self, port: int) -> None:
        self.process = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, str(port), str(REPO)], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, bufsize=1)
        assert self.process.stdout is not None
        json.loads(self.process.stdout.readline())

    def counts(self) -> dict[str, int]:
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.write("?\n")
        self.process.stdin.flush()
        return json.loads(self.process.stdout.readline())

    def close(self) -> None:
        self.process.kill()
        self.process.wait(timeout=10)


async def rebirth_times(port: int, rounds: int, devices: int) -> list[tuple[float, float]]:
    """(seconds to the NBIRTH, seconds to the last DBIRTH) after each NCMD Rebirth."""
    from softplc.core.clock import RealClock
    from softplc.protocols.mqtt import MqttConnection
    from softplc.protocols.mqtt_settings import MqttSettings
    from softplc.protocols.sparkplug import sparkplug_b_pb2 as pb

    arrivals: list[tuple[str, float]] = []
    host = MqttConnection(MqttSettings(port=port), "bench-host", RealClock())
    host.subscribe("spBv1.0/bench/NBIRTH/#", lambda topic, payload, retained: arrivals.append(("N", time.monotonic())))
    host.subscribe("spBv1.0/bench/DBIRTH/#", lambda topic, payload, retained: arrivals.append(("D", time.monotonic())))
    task = asyncio.create_task(host.run())
    times = []
    try:
        while not host.connected:
            await asyncio.sleep(0.01)
        for _ in range(rounds):
            arrivals.clear()
            payload = pb.Payload(timestamp=int(time.time() * 1000))
            payload.metrics.add(name="Node Control/Rebirth", datatype=11, boolean_value=True)
            sent = time.monotonic()
            await host.publish("spBv1.0/bench/NCMD/node", payload.SerializeToString())
            deadline = sent + 10
            while sum(kind == "D" for kind, _ in arrivals) < devices and time.monotonic() < deadline:
                await asyncio.sleep(0.002)
            nbirth = next((at for kind, at in arrivals if kind == "N"), float("inf"))
            dbirths = [at for kind, at in arrivals if kind == "D"]
            times.append((nbirth - sent, (max(dbirths) if len(dbirths) >= devices else float("inf")) - sent))
            await asyncio.sleep(0.3)
    finally:
        task.cancel()
        await host.close()
    return times


async def measure(args: argparse.Namespace, state: Path, port: int) -> dict[str, object]:
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.config import parse_config
    from softplc.core.clock import RealClock

    config = parse_config(plant(args.tags, args.interval, args.devices, port, not args.baseline), state / "tagdb.yaml")
    runtime = Runtime(config, RealClock(), state_dir=state)
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    subscriber = None if args.baseline else Subscriber(port)
    edge = next((adapter for adapter in runtime.adapters if adapter.name == "sparkplug"), None)
    await runtime.start()
    try:
        await asyncio.sleep(args.warmup)
        probe = next(task for task in runtime.tasks if task.name == "probe")
        probe.stats.latency.reset()
        started, cpu_before, ticks_before = time.monotonic(), time.process_time(), runtime.db.value("tick")
        published_before = edge.status.metrics if edge else 0
        messages_before = edge.status.messages if edge else 0
        received_before = subscriber.counts() if subscriber else {"metrics": 0, "messages": 0}
        cycles_before = probe.stats.cycles
        await asyncio.sleep(args.seconds)
        elapsed = time.monotonic() - started
        cpu = time.process_time() - cpu_before
        latency = probe.stats.latency.summary()
        published = (edge.status.metrics - published_before) if edge else 0
        messages = (edge.status.messages - messages_before) if edge else 0
        produced = (runtime.db.value("tick") - ticks_before) * args.tags
        cycles = probe.stats.cycles - cycles_before
        overruns = sum(task.stats.overruns for task in runtime.tasks)
        await asyncio.sleep(1.0)  # what is on its way arrives
        received = subscriber.counts() if subscriber else {"metrics": 0, "messages": 0}
        rebirths = [] if args.baseline else await rebirth_times(port, args.rebirths, args.devices)
    finally:
        await runtime.stop()
        if subscriber:
            subscriber.close()
    return {"elapsed": elapsed, "cpu": cpu / elapsed, "latency": latency, "produced": produced / elapsed,
            "published": published / elapsed, "messages": messages / elapsed, "cycles": cycles, "overruns": overruns,
            "received": (received["metrics"] - received_before["metrics"]) / elapsed, "rebirths": rebirths}


def publishing_cost(tags: int, devices: int, rounds: int = 200) -> float:
    """CPU µs per metric change on the event loop: noting the change (on_change) and building the DDATAs,
    measured with thread CPU time, so a busy machine does not inflate it (the socket writes are not in it)."""
    from softplc.adapters.sparkplug.edge_node import EdgeNode
    from softplc.adapters.sparkplug.settings import SparkplugSettings
    from softplc.config import parse_config
    from softplc.core.tags import Tag
    from softplc.protocols.mqtt_settings import MqttSettings
    from softplc.protocols.sparkplug import payloads

    config = parse_config(plant(tags, "10ms", devices, 1883, True), Path("/nonexistent/tagdb.yaml"))
    node = EdgeNode(SparkplugSettings.from_config(config), MqttSettings())
    batch = [Tag(definition, 1_767_225_600.0) for definition in config.tags if definition.name.startswith("v")]
    started = time.thread_time()
    for round_number in range(rounds):
        for tag in batch:
            tag.value = round_number + 0.5
        node.changes.note(batch)  # the adapter's own hot path, without a broker
        for _, metrics in node.changes.batches(node.changes.take()):
            payloads.encode_data(1_767_225_600_000, 1, metrics, by_alias=True)
    return (time.thread_time() - started) / (rounds * len(batch)) * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # 600: more than the goal is offered, so that "published >= 50,000/s" can be met by keeping
    # up (at exactly 50,000/s offered, a 30 s window of a plant keeping up reads 49,99x).
    parser.add_argument("--tags", type=int, default=600, help="tags changing at every scan of the flood task (default 600)")
    parser.add_argument("--interval", default="10ms", help="flood task interval (default 10ms)")
    parser.add_argument("--devices", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup", type=float, default=3.0)
    parser.add_argument("--rebirths", type=int, default=10)
    parser.add_argument("--baseline", action="store_true", help="the same plant without the edge node")
    args = parser.parse_args()
    from tests.mosquitto_server import MosquittoServer

    load_before = load_average()
    broker = MosquittoServer()
    broker.start()
    try:
        with tempfile.TemporaryDirectory(prefix="softplc-sparkplug-") as directory:
            result = asyncio.run(measure(args, Path(directory), broker.port))
    finally:
        broker.remove()
    latency = result["latency"]
    what = "baseline, no edge node" if args.baseline else f"Sparkplug B, {args.devices} devices"
    print(f"{what}: {args.tags} tags every {args.interval}, {args.seconds:g} s measured (load before {load_before}, after {load_average()})")
    print(f"  produced {result['produced']:,.0f} changes/s; published {result['published']:,.0f} metric changes/s in "
          f"{result['messages']:,.0f} messages/s; the subscriber received {result['received']:,.0f}/s; process CPU {result['cpu'] * 100:.0f} % of one core")
    print(f"  10 ms probe task start latency: mean {latency['mean']:.3f} ms, p99 {latency['p99']:.3f} ms, max {latency['max']:.3f} ms "
          f"({result['cycles']} cycles; overruns of all tasks {result['overruns']})")
    if args.baseline:
        return 0
    rebirths = result["rebirths"]
    to_nbirth = [first for first, _ in rebirths]
    to_all = [last for _, last in rebirths]
    print(f"  rebirth ({len(rebirths)} NCMDs): NBIRTH after median {statistics.median(to_nbirth) * 1e3:.1f} ms, max {max(to_nbirth) * 1e3:.1f} ms; "
          f"all {args.devices} DBIRTHs after median {statistics.median(to_all) * 1e3:.1f} ms, max {max(to_all) * 1e3:.1f} ms")
    cost = publishing_cost(args.tags, args.devices)
    print(f"  publishing cost (thread CPU time, {args.tags} changes x 200 batches): {cost:.2f} µs per metric change on the event loop "
          f"→ {1e6 / cost:,.0f} changes/s per core before the socket writes")
    rate_ok = result["published"] >= GOAL_RATE and result["received"] >= GOAL_RATE
    p99_ok = latency["p99"] <= GOAL_P99_MS
    rebirth_ok = max(to_all) <= GOAL_REBIRTH_S
    for ok, goal in ((rate_ok, f">= {GOAL_RATE:,} metric changes/s published and received"), (p99_ok, f"10 ms task p99 <= {GOAL_P99_MS} ms"),
                     (rebirth_ok, f"rebirth (last DBIRTH) <= {GOAL_REBIRTH_S} s after the NCMD")):
        print(f"  goal {goal}: {'met' if ok else 'GOAL MISSED'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
