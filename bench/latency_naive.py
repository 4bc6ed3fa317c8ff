"""The naive setup a user might write instead of softplc, for the case IV handshake baseline.

Server: a plain asyncua `Server()` with default settings, Ready / TaskID / Delay / ReadyStamp
variables, and a Python loop that does the PLC's job every `scan` seconds with
`node.read_value()` / `node.write_value()` and `asyncio.sleep(scan)`.

Client (a separate process, like the thesis's Python program): polls Ready with `read_value()`
every 10 ms; when it is set, writes the next TaskID and clears Ready with two `write_value()`
calls, then (not timed) reads ReadyStamp so the bench can join its answer with the server's
record. It prints one JSON line per answer, with the same fields as softplc's client.

    python bench/latency_naive.py client opc.tcp://127.0.0.1:4850/naive/ --samples 100
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time
from dataclasses import dataclass, field

from asyncua import Client, Server

NAMESPACE = "urn:naive:handshake"
SCENARIOS = {"slow": (10.0, 20.0, 30.0), "average": (1.0, 2.0, 5.0), "fast": (0.1, 0.2, 0.5)}


@dataclass
class NaiveRecord:
    """One handshake as the naive server's loop saw it."""

    ready_stamp: float
    delay_ms: float  # loop time from setting Ready to seeing the new TaskID
    loops: int  # loop iterations in between


@dataclass
class NaiveServer:
    """A plain asyncua server plus a Python loop doing the PLC logic."""

    endpoint: str
    scenario: str
    scan: float
    records: list[NaiveRecord] = field(default_factory=list)

    async def run(self, started: asyncio.Event, stop: asyncio.Event) -> None:
        server = Server()
        await server.init()
        server.set_endpoint(self.endpoint)
        index = await server.register_namespace(NAMESPACE)
        handshake = await server.nodes.objects.add_object(index, "Handshake")
        ready = await handshake.add_variable(index, "Ready", False)
        task_id = await handshake.add_variable(index, "TaskID", 0)
        delay = await handshake.add_variable(index, "Delay", 0.0)
        stamp = await handshake.add_variable(index, "ReadyStamp", 0.0)
        await ready.set_writable()
        await task_id.set_writable()
        durations = SCENARIOS[self.scenario]
        async with server:
            started.set()
            active, waiting, task_started = 0, False, 0.0
            ready_at, loops = 0.0, 0
            while not stop.is_set():
                now = time.monotonic()
                requested = await task_id.read_value()
                if waiting:
                    loops += 1
                if requested in (1, 2, 3) and requested != active:
                    if waiting and active:
                        self.records.append(NaiveRecord(ready_at, (now - ready_at) * 1000.0, loops))
                        await delay.write_value((now - ready_at) * 1000.0)
                    active, waiting, task_started = requested, False, now
                if not waiting and (active == 0 or now - task_started >= durations[active - 1]):
                    waiting, ready_at, loops = True, time.monotonic(), 0
                    await stamp.write_value(ready_at)
                    await ready.write_value(True)
                await asyncio.sleep(self.scan)


async def naive_client(endpoint: str, samples: int, poll: float) -> None:
    """Poll Ready, answer with two writes; print a JSON line per answer (first one is the warm-up)."""
    async with Client(endpoint) as client:
        index = await client.get_namespace_index(NAMESPACE)
        handshake = await client.nodes.objects.get_child(f"{index}:Handshake")
        ready = await handshake.get_child(f"{index}:Ready")
        task_id = await handshake.get_child(f"{index}:TaskID")
        stamp = await handshake.get_child(f"{index}:ReadyStamp")
        next_task, answered = 1, 0
        while answered <= samples:
            value = await ready.read_value()
            t_seen = time.monotonic()
            # Ready stays low from our own clear until the server sets it for the next task, so a
            # high Ready is always a new one (waiting to see it low first hung for good when a busy
            # machine delayed the next poll past the shortest task, 100 ms).
            if value:
                t_sent = time.monotonic()
                await task_id.write_value(next_task)
                await ready.write_value(False)
                t_done = time.monotonic()
                ready_stamp = await stamp.read_value()
                kind = "warmup" if answered == 0 else "sample"
                print(json.dumps({"type": kind, "index": answered, "task_id": next_task, "ready_stamp": ready_stamp,
                                  "t_seen": t_seen, "t_sent": t_sent, "t_done": t_done}), flush=True)
                answered += 1
                next_task = next_task % 3 + 1
            await asyncio.sleep(poll)
        print(json.dumps({"type": "done"}), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    client = commands.add_parser("client", help="the naive polling client")
    client.add_argument("endpoint")
    client.add_argument("--samples", type=int, default=100)
    client.add_argument("--poll", type=float, default=0.01, help="seconds between reads of Ready (default 0.01)")
    args = parser.parse_args()
    asyncio.run(naive_client(args.endpoint, args.samples, args.poll))
    return 0


if __name__ == "__main__":
    sys.exit(main())
