"""Where the time of one OPC UA handshake goes: time stamps on both sides of `softplc latency`.

Runs the case IV handshake like `softplc latency --protocol opcua` (our runtime here, the client in
its own process), with time stamps taken where messages enter and leave each process, and prints
per step the median and p90 of the wall time and the median CPU time (thread time) the step cost
its process:

    Ready set in the scan → the publisher writes it into the address space  server
    → the PublishResponse carrying it is on the wire                   server
    → the client has received it                                       (kernel, scheduling)
    → the client's publish loop hands Ready over (t_seen)              client
    → the answer's Write is on the wire                                client
    → the server has received it                                       (kernel, scheduling)
    → the WriteResponse is on the wire                                 server (with any Publish request served first)
    → the client has received it                                       (kernel, scheduling)
    → the write is acknowledged (t_done)                               client

Wall times include waiting for a CPU (other processes on the machine); CPU times do not, so they
compare code between runs on a busy machine. The stamps are taken by wrapping asyncua's and
softplc's methods in both processes (bench-only instrumentation, a few µs per stamp).

    .venv/bin/python bench/latency_trace.py [--samples 200] [--scan 1] [--scenario fast] [--pin]

`--pin` places the two sides as bench/latency_baseline.py does by default: our runtime (this
process) on the first CPU, the client on the last.
"""

from __future__ import annotations

import argparse
import asyncio
import atexit
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

Event = tuple[str, float, float, Any]  # kind, monotonic s, thread CPU s, detail
CLIENT_FLAG = "--as-traced-client"


def _stamp(events: list[Event], kind: str, detail: Any = None) -> None:
    events.append((kind, time.monotonic(), time.thread_time(), detail))


def trace_server(events: list[Event]) -> None:
    """Stamp what the server receives and sends, and when the publisher starts a push."""
    from asyncua import ua
    from asyncua.server.address_space import AddressSpace

    from softplc.adapters.opcua import processor, transport

    received = transport.GuardedProtocol.data_received

    def data_received(self: Any, data: bytes) -> None:
        _stamp(events, "in")
        received(self, data)

    sent = processor.GuardedProcessor.send_response

    def send_response(self: Any, handle: Any, seqhdr: Any, response: Any, *args: Any) -> None:
        sent(self, handle, seqhdr, response, *args)
        kind = type(response).__name__
        if isinstance(response, ua.PublishResponse) and response.Parameters.NotificationMessage.NotificationData:
            kind += " with data"
        _stamp(events, "out", kind)

    write = AddressSpace.write_attribute_value

    async def write_attribute_value(self: Any, node_id: ua.NodeId, attribute: Any, value: Any) -> Any:
        if node_id.Identifier == "Ready" and value.Value is not None and value.Value.Value:
            _stamp(events, "push")  # the publisher mirrors Ready's rise into the address space
        return await write(self, node_id, attribute, value)

    serve = processor.GuardedProcessor._process_message

    async def process_message(self: Any, typeid: ua.NodeId, *args: Any) -> Any:
        _stamp(events, "serve", typeid.Identifier)
        return await serve(self, typeid, *args)

    transport.GuardedProtocol.data_received = data_received  # type: ignore[method-assign]
    processor.GuardedProcessor.send_response = send_response  # type: ignore[method-assign]
    AddressSpace.write_attribute_value = write_attribute_value  # type: ignore[method-assign]
    processor.GuardedProcessor._process_message = process_message  # type: ignore[method-assign]


def run_traced_client(argv: list[str], path: str) -> int:
    """The latency client, stamping what it receives and sends; the stamps go to `path` at exit."""
    from asyncua import ua
    from asyncua.client import ua_client

    from softplc.latency import client
    from softplc.latency.opcua_driver import OpcuaDriver

    events: list[Event] = []
    received = ua_client.UASocketProtocol.data_received

    def data_received(self: Any, data: bytes) -> None:
        _stamp(events, "in")
        received(self, data)

    send = ua_client.UASocketProtocol._send_request

    def send_request(self: Any, request: Any, timeout: float = 1, message_type: Any = ua.MessageType.SecureMessage) -> Any:
        future = send(self, request, timeout, message_type)
        _stamp(events, "out", type(request).__name__)
        return future

    write = OpcuaDriver._write

    async def answered(self: Any, task_id: int) -> None:
        await write(self, task_id)
        _stamp(events, "acked")

    ua_client.UASocketProtocol.data_received = data_received  # type: ignore[method-assign]
    ua_client.UASocketProtocol._send_request = send_request  # type: ignore[method-assign]
    OpcuaDriver._write = answered  # type: ignore[method-assign]
    atexit.register(lambda: Path(path).write_text(json.dumps(events)))
    return client.main(argv)


def _first(events: list[Event], after: float, kind: str, detail: Any = None, before: float | None = None) -> Event | None:
    for event in events:
        if event[1] >= after and event[0] == kind and (detail is None or event[3] == detail):
            return event if before is None or event[1] <= before else None
    return None


def _last(events: list[Event], before: float, kind: str) -> Event | None:
    found = None
    for event in events:
        if event[1] > before:
            break
        if event[0] == kind:
            found = event
    return found


STEPS = (
    ("Ready set → publisher mirrors it", "server"),
    ("→ PublishResponse on the wire", "server"),
    ("→ client received it", "wire"),
    ("→ publish loop hands Ready over (seen)", "client"),
    ("→ Write on the wire (CPU: from received)", "client"),
    ("→ server received it", "wire"),
    ("→ WriteResponse on the wire", "server"),
    ("→ client received it", "wire"),
    ("→ acknowledged", "client"),
)


def breakdown(server: list[Event], client: list[Event], samples: list[Any]) -> tuple[list[list[float]], list[list[float]], list[int]]:
    """Per step: wall times and CPU times (s) over the samples; and the Publish requests served before each Write."""
    from asyncua import ua

    walls: list[list[float]] = [[] for _ in STEPS]
    cpus: list[list[float]] = [[] for _ in STEPS]
    publishes: list[int] = []
    for sample in samples:
        ready, done = sample.ready_stamp, sample.t_done
        push = _first(server, ready, "push", before=done)
        published = _first(server, ready, "out", "PublishResponse with data", done)
        if push is None or published is None:
            continue
        # Each side stamps a message it sends once the send returned, so the other may stamp its
        # arrival first: arrivals are found from what they led to. The notification arrived last
        # before the client saw Ready; the server's part starts with the first request it received
        # after that; the WriteResponse arrived last before the acknowledgement.
        client_in = _last(client, sample.t_seen, "in")
        write_out = _first(client, ready, "out", "WriteRequest", done)
        write_done = _first(server, ready, "out", "WriteResponse", done)
        acked = _first(client, sample.t_sent, "acked")
        if client_in is None or write_out is None or write_done is None or acked is None:
            continue
        server_in = _first(server, client_in[1], "in", before=write_done[1])
        answer_in = _last(client, acked[1], "in")
        if server_in is None or answer_in is None:
            continue
        publishes.append(sum(1 for event in server if server_in[1] <= event[1] <= write_done[1]
                             and event[0] == "serve" and event[3] == ua.ObjectIds.PublishRequest_Encoding_DefaultBinary))
        times = [ready, push[1], published[1], client_in[1], sample.t_seen, write_out[1], server_in[1], write_done[1], answer_in[1], done]
        for index in range(len(STEPS)):
            walls[index].append(times[index + 1] - times[index])
        # CPU where one process works through a step without waiting on the other: the client's
        # steps 4 and 5 run in one go, so their CPU is given once, at step 5.
        cpus[1].append(published[2] - push[2])
        cpus[4].append(write_out[2] - client_in[2])
        cpus[6].append(write_done[2] - server_in[2])
        cpus[8].append(acked[2] - answer_in[2])
    return walls, cpus, publishes


def report(walls: list[list[float]], cpus: list[list[float]], publishes: list[int]) -> list[str]:
    lines = ["| step | where | wall median (ms) | wall p90 (ms) | CPU median (ms) |", "|---|---|---:|---:|---:|"]
    cpu_total = sum(statistics.median(cpu) for cpu in cpus if cpu)
    for (name, where), wall, cpu in zip(STEPS, walls, cpus):
        ordered = sorted(wall)
        p90 = ordered[min(len(ordered) - 1, int(0.9 * len(ordered)))] if ordered else float("nan")
        cpu_text = f"{statistics.median(cpu) * 1e3:.3f}" if cpu else ""
        lines.append(f"| {name} | {where} | {statistics.median(wall) * 1e3:.3f} | {p90 * 1e3:.3f} | {cpu_text} |")
    totals = [sum(step[i] for step in walls) for i in range(len(walls[0]))]
    lines.append(f"| **Ready set → acknowledged** | | {statistics.median(totals) * 1e3:.3f} | "
                 f"{sorted(totals)[int(0.9 * len(totals))] * 1e3:.3f} | {cpu_total * 1e3:.3f} |")
    lines.append(f"\n{len(totals)} handshakes traced; Publish requests the server served between the notification's "
                 f"arrival at the client and the WriteResponse: {statistics.mean(publishes):.2f} per handshake")
    return lines


async def traced_run(args: argparse.Namespace) -> tuple[list[Event], list[Event], list[Any], dict[str, Any]]:
    from bench.latency_baseline import placement
    from softplc.latency import client_process
    from softplc.latency.measurement import Target, measure

    server: list[Event] = []
    trace_server(server)
    with tempfile.TemporaryDirectory(prefix="latency-trace-") as folder:
        client_file = str(Path(folder) / "client.json")
        command = client_process.client_command

        def traced_command(target: Any, endpoint: str) -> list[str]:
            argv = command(target, endpoint)
            return [argv[0], str(Path(__file__).resolve()), CLIENT_FLAG, client_file, *argv[3:]]

        client_process.client_command = traced_command  # type: ignore[assignment]
        places = placement(not args.pin)
        if places:
            os.sched_setaffinity(0, places[0])
        result = await measure(Target("opcua", args.scenario, args.scan / 1000.0, samples=args.samples,
                                      client_cpus=places[1] if places else None))
        client = json.loads(Path(client_file).read_text()) if Path(client_file).exists() else []
    return server, client, result.samples, result.conditions


def main() -> int:
    if len(sys.argv) > 2 and sys.argv[1] == CLIENT_FLAG:
        return run_traced_client(sys.argv[3:], sys.argv[2])
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--scan", type=float, default=1.0, metavar="MS")
    parser.add_argument("--scenario", choices=("slow", "average", "fast"), default="fast")
    parser.add_argument("--pin", action="store_true", help="our runtime on the first CPU, the client on the last")
    args = parser.parse_args()
    load = os.getloadavg()
    server, client, samples, conditions = asyncio.run(traced_run(args))
    walls, cpus, publishes = breakdown(server, client, samples)
    if not publishes:
        print("no handshake could be traced", file=sys.stderr)
        return 1
    print("\n".join(report(walls, cpus, publishes)))
    print(f"load average {tuple(round(x, 2) for x in load)} before, CPUs {conditions.get('cpu_busy_percent')} % busy during the run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
