"""OPC UA round trips and subscription delivery latency against `softplc run` in its own process.

The plant has 1,000 tags; a 10 ms task rewrites 10 of them and a counter every scan. The
asyncua client (this process, SecurityPolicy None, user with the operator role) measures:

- read: `read_value` of one tag; read x100: one Read of 100 tags;
- write: `write_value` of one tag (answered once validated and journaled);
- write-to-visible: a write (at a random phase of the cycle) until a read returns the new
  value (applied at the next cycle boundary of the 10 ms task, so ~5 ms on average by design);
- delivery: subscription notification arrival (client wall clock) minus the tag's source
  timestamp (when the scan committed the change, server wall clock; same machine), for a
  subscription with publishing interval 0 (publish as soon as a change is queued) and 10 ms.

The server's 10 ms task start latency while being queried comes from its exit statistics.
Goals (issue 3): delivery p99 <= 5 ms; the 10 ms task's p99 start latency <= 1 ms.

    .venv/bin/python bench/opcua_roundtrip.py [--count 1000] [--seconds 10]

`--floor MS` measures instead the floor of the case IV handshake at a MS scan (what
bench/latency_baseline.py compares softplc's handshake with, in the same run): the mean delivery
of a sparse change (a tag the task stamps with its scan's monotonic time every 100 ms → the
PublishResult in the client's publish loop, before any dispatch) plus the mean round trip of one
Write of a uint16 and a bool (the answer's shape), both by a bare asyncua client. The writes go at
the pace of the changes (one every 100 ms; a handshake's answers come 100-500 ms apart): a write right after
the previous one, with both processes' CPUs still awake, took 0.4-0.6 ms on this machine, one
after 100 ms of quiet 1.3 ms (2026-11-27) — measured back-to-back, the floor would hold the
handshake to a speed no handshake client has. The back-to-back mean is printed beside it.

    .venv/bin/python bench/opcua_roundtrip.py --floor 1 [--count 200]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from asyncua import Client, ua  # noqa: E402
from opcua_common import (  # noqa: E402
    PASSWORD,
    USER,
    changing_tags,
    floor_plant_yaml,
    goal,
    on_publish,
    percentile,
    plant_yaml,
    start_server,
    task_latency,
)

from softplc.util.realtime import format_cpus  # noqa: E402  (opcua_common put the repository on the path)

DELIVERY_GOAL_MS = 5.0
LATENCY_GOAL_MS = 1.0


def summary(label: str, samples: list[float]) -> str:
    ms = [s * 1e3 for s in samples]
    return f"| {label} | {len(ms)} | {percentile(ms, 0.5):.2f} | {percentile(ms, 0.99):.2f} | {max(ms):.2f} |"


class Delivery:
    def __init__(self) -> None:
        self.delays: list[float] = []

    def datachange_notification(self, node, value, data) -> None:  # only until on_publish takes over
        pass

    def item(self, notification) -> None:
        arrived = time.time()
        stamp = notification.Value.SourceTimestamp
        if stamp is not None:
            self.delays.append(arrived - stamp.timestamp())


async def run(endpoint: str, count: int, seconds: float, changing: list[str]) -> list[tuple[str, list[float]]]:
    results: list[tuple[str, list[float]]] = []
    client = Client(endpoint, timeout=10)
    client.set_user(USER)
    client.set_password(PASSWORD)
    async with client:
        ns = await client.get_namespace_index("urn:softplc:tags")
        still = client.get_node(ua.NodeId("c01_v04", ns))
        hundred = [ua.NodeId(f"c{1 + i // 50:02d}_v{i % 50:02d}", ns) for i in range(100)]
        target = client.get_node(ua.NodeId("c02_v01", ns))
        for _ in range(50):  # warm up
            await still.read_value()
        samples = []
        for _ in range(count):
            started = time.perf_counter()
            await still.read_value()
            samples.append(time.perf_counter() - started)
        results.append(("read, 1 tag", samples))
        samples = []
        for _ in range(max(10, count // 10)):
            started = time.perf_counter()
            await client.read_values([client.get_node(n) for n in hundred])
            samples.append(time.perf_counter() - started)
        results.append(("read, 100 tags in one request", samples))
        samples = []
        for index in range(count):
            started = time.perf_counter()
            await target.write_value(ua.Variant(index, ua.VariantType.Int32))
            samples.append(time.perf_counter() - started)
        results.append(("write, 1 tag (accepted into the journal)", samples))
        samples = []
        for index in range(max(10, count // 5)):
            value = 1_000_000 + index
            # A random phase: otherwise each write follows the cycle that made the last one
            # visible, and always waits almost a whole interval.
            await asyncio.sleep(random.uniform(0, 0.01))
            started = time.perf_counter()
            await target.write_value(ua.Variant(value, ua.VariantType.Int32))
            while await target.read_value() != value:
                pass
            samples.append(time.perf_counter() - started)
        results.append(("write → visible in a read (next cycle boundary)", samples))
        for period in (0, 10):
            handler = Delivery()
            subscription = await client.create_subscription(period, handler)
            on_publish(client, subscription, handler.item)
            await subscription.subscribe_data_change([client.get_node(ua.NodeId(changing[0], ns))], queuesize=100)
            await asyncio.sleep(0.5)
            handler.delays.clear()
            await asyncio.sleep(seconds)
            await subscription.delete()
            results.append((f"subscription delivery, publishing interval {period} ms", handler.delays))
    return results


@dataclass
class Floor:
    """What the protocol alone costs one handshake: a delivery plus a write, by a bare asyncua client."""

    scan_ms: float
    delivery: list[float]  # s: the scan's stamp → the PublishResult in the client's publish loop
    write: list[float]  # s: a Write of a uint16 and a bool sent → acknowledged, one every change_every_ms
    write_back_to_back: list[float] = field(default_factory=list)  # s: the same Write, each right after the last

    @property
    def delivery_ms(self) -> float:
        return statistics.fmean(self.delivery) * 1e3

    @property
    def write_ms(self) -> float:
        return statistics.fmean(self.write) * 1e3

    @property
    def mean_ms(self) -> float:
        return self.delivery_ms + self.write_ms

    @property
    def median_ms(self) -> float:
        """The same of medians (a busy machine's stalls shift them less)."""
        return (statistics.median(self.delivery) + statistics.median(self.write)) * 1e3

    @classmethod
    def joined(cls, floors: list[Floor]) -> Floor:
        """One floor of the samples of several measurements (e.g. before and after a run)."""
        return cls(floors[0].scan_ms, [s for f in floors for s in f.delivery], [s for f in floors for s in f.write],
                   [s for f in floors for s in f.write_back_to_back])

    def describe(self) -> str:
        return (f"floor at a {self.scan_ms:g} ms scan: {self.mean_ms:.3f} ms = delivery {self.delivery_ms:.3f} "
                f"(median {statistics.median(self.delivery) * 1e3:.3f}, {len(self.delivery)} changes) + write "
                f"{self.write_ms:.3f} (median {statistics.median(self.write) * 1e3:.3f}, {len(self.write)} writes at the changes' pace), means"
                + (f"; back-to-back writes {statistics.fmean(self.write_back_to_back) * 1e3:.3f} ms "
                   f"(floor {self.delivery_ms + statistics.fmean(self.write_back_to_back) * 1e3:.3f} ms with them)"
                   if self.write_back_to_back else ""))


async def measure_floor(endpoint: str, scan_ms: float, samples: int, writes: int, change_every_ms: float = 100.0) -> Floor:
    """Delivery of `samples` sparse changes, then `writes` writes at the same pace, and as many back-to-back (floor_plant_yaml's plant)."""
    client = Client(endpoint, timeout=10)
    client.set_user(USER)
    client.set_password(PASSWORD)
    async with client:
        ns = await client.get_namespace_index("urn:softplc:tags")
        delivery: list[float] = []
        enough = asyncio.Event()

        def item(notification) -> None:
            arrived = time.monotonic()
            stamp = notification.Value.Value.Value if notification.Value and notification.Value.Value else None
            if stamp:
                delivery.append(arrived - stamp)
                if len(delivery) > samples:
                    enough.set()

        subscription = await client.create_subscription(0, Delivery())
        on_publish(client, subscription, item)
        await subscription.subscribe_data_change(client.get_node(ua.NodeId("stamp", ns)), queuesize=1)
        await asyncio.wait_for(enough.wait(), timeout=3 * samples * change_every_ms / 1e3 + 30)
        await subscription.delete()
        delivery = delivery[1:samples + 1]  # the first is the value at subscribing, not a change
        nodes = [client.get_node(ua.NodeId("answer", ns)), client.get_node(ua.NodeId("flag", ns))]
        write: list[float] = []
        back_to_back: list[float] = []
        for paced, measured in ((True, write), (False, back_to_back)):
            for index in range(writes + 10):
                values = [ua.DataValue(ua.Variant(index % 3 + 1, ua.VariantType.UInt16)), ua.DataValue(ua.Variant(bool(index % 2), ua.VariantType.Boolean))]
                if paced:
                    await asyncio.sleep(change_every_ms / 1e3)
                started = time.monotonic()
                await client.write_values(nodes, values)
                if index >= 10:  # after a warm-up
                    measured.append(time.monotonic() - started)
    return Floor(scan_ms, delivery, write, back_to_back)


async def floor_at(scan_ms: float, samples: int = 200, writes: int = 500, change_every_ms: float = 100.0,
                   placement: tuple[frozenset[int], frozenset[int]] | None = None) -> Floor:
    """Serve floor_plant_yaml with `softplc run` in its own process and measure the floor against it.

    `placement` (server CPUs, client CPUs): `softplc run --cpus` the first, this process (the
    client) kept on the second while it measures, as latency_baseline.py places every setup.
    """
    with tempfile.TemporaryDirectory() as tmp:
        extra = ("--cpus", format_cpus(placement[0])) if placement else ()
        server = start_server(Path(tmp) / "floor", floor_plant_yaml(scan_ms, change_every_ms), *extra)
        mine = os.sched_getaffinity(0)
        try:
            if placement:
                os.sched_setaffinity(0, placement[1])
            return await measure_floor(server.endpoint, scan_ms, samples, writes, change_every_ms)
        finally:
            if placement:
                os.sched_setaffinity(0, mine)
            server.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--nice", type=int, default=0, help="run the server (and its baseline) at this niceness, e.g. -10 (root)")
    parser.add_argument("--floor", type=float, metavar="MS", help="measure the case IV handshake's floor at a MS scan instead")
    args = parser.parse_args()
    if args.floor is not None:
        print(asyncio.run(floor_at(args.floor, samples=min(args.count, 200), writes=min(args.count, 200))).describe())
        return 0
    yaml_text = plant_yaml(1000, changing=10)
    with tempfile.TemporaryDirectory() as tmp:
        baseline = start_server(Path(tmp) / "baseline", yaml_text, opcua=False, nice=args.nice)
        time.sleep(args.seconds)
        baseline_latency = task_latency(baseline.stop())
        server = start_server(Path(tmp) / "served", yaml_text, nice=args.nice)
        try:
            wait = server.cpu_wait_seconds()
            started = time.perf_counter()
            results = asyncio.run(run(server.endpoint, args.count, args.seconds, changing_tags(yaml_text)))
            wait_share = (server.cpu_wait_seconds() - wait) / (time.perf_counter() - started)
        finally:
            output = server.stop()
    latency = task_latency(output)
    print("| operation | samples | p50 ms | p99 ms | max ms |")
    print("|---|---:|---:|---:|---:|")
    for label, samples in results:
        print(summary(label, samples))
    print(f"\n10 ms task start latency meanwhile: p99 {latency['p99']:.3f} ms, max {latency['max']:.3f} ms, "
          f"mean {latency['mean']:.3f} ms over {latency['cycles']:.0f} cycles, {latency['overruns']:.0f} overruns; "
          f"the server waited for a CPU {wait_share:.0%} of the time")
    print(f"the same plant without OPC UA (nobody querying): p99 {baseline_latency['p99']:.3f} ms, max {baseline_latency['max']:.3f} ms")
    ok = True
    for label, samples in results:
        if label.startswith("subscription delivery, publishing interval 0"):
            ok = goal("delivery p99 (ms), publishing interval 0", percentile(samples, 0.99) * 1e3, DELIVERY_GOAL_MS) and ok
    ok = goal("10 ms task p99 start latency (ms)", latency["p99"], LATENCY_GOAL_MS) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
