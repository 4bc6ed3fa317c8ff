"""A Modbus link of 1,000 registers polled every 100 ms: requests per poll, and the poll's timing.

The remote is pymodbus's own server (a SimDevice) in a separate process; it counts the requests
it answers and changes every register at each read. A runtime here binds 1,000 int16 tags to its
holding registers 0..999 and polls them every 100 ms: the link groups contiguous registers, so a
poll should be 8 requests of 125 registers. Measured for `--seconds`: the requests the server saw
per poll, the polls per second, each poll's duration (first request to last answer) and the
interval between polls, and that every tag is GOOD with the remote's latest values.

Goals (issue 26): ≤ 10 requests per poll, polled at 100 ms (mean interval ≤ 110 ms).

    .venv/bin/python bench/links_modbus_poll.py [--registers 1000] [--seconds 10]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

GOAL_REQUESTS = 10
GOAL_INTERVAL_MS = 110.0
PERIOD_MS = 100.0


async def serve(registers: int) -> None:
    """The remote: pymodbus's server on a free port; prints it, then answers `count` on stdin with its request count."""
    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import DataType, SimData, SimDevice

    requests = 0

    async def action(function: int, start: int, address: int, count: int, values: list[int], written: object) -> None:
        nonlocal requests
        requests += 1
        for offset in range(count):  # every read sees new values
            values[address - start + offset] = (address + offset + requests) & 0x7FFF
        return None

    device = SimDevice(1, simdata=([SimData(0, values=[False] * 16, datatype=DataType.BITS)], [SimData(0, values=[False] * 16, datatype=DataType.BITS)],
                                   [SimData(0, values=[0] * registers, datatype=DataType.REGISTERS)], [SimData(0, values=[0] * 16, datatype=DataType.REGISTERS)]),
                       action=action)
    server = ModbusTcpServer(device, address=("127.0.0.1", 0))
    await server.serve_forever(background=True)
    print(server.transport.sockets[0].getsockname()[1], flush=True)  # type: ignore[union-attr]
    loop = asyncio.get_running_loop()
    while line := await loop.run_in_executor(None, sys.stdin.readline):  # the bench's end closes our stdin
        if line.strip() == "count":
            print(requests, flush=True)
    await server.shutdown()


def plant(port: int, registers: int) -> str:
    lines = ["plant: {name: bench}", "links:",
             f"  remote: {{protocol: modbus, host: 127.0.0.1, port: {port}, period: {PERIOD_MS:g}ms, timeout: 2s}}", "tags:"]
    lines += [f"  r{i}: {{type: int16, link: {{name: remote, source: 'holding:{i}'}}}}" for i in range(registers)]
    lines += ["tasks:", "  main: {interval: 10ms}", "servers:", "  opcua: {enabled: false}", "  modbus: {enabled: false}", "  hmi: {enabled: false}"]
    return "\n".join(lines) + "\n"


def count(remote: subprocess.Popen[str]) -> int:
    assert remote.stdin is not None and remote.stdout is not None
    remote.stdin.write("count\n")
    remote.stdin.flush()
    return int(remote.stdout.readline())


async def measure(remote: subprocess.Popen[str], port: int, registers: int, seconds: float, folder: Path) -> int:
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.config import load_config
    from softplc.core.clock import RealClock
    from softplc.core.tags import Quality

    path = folder / "plant.yaml"
    path.write_text(plant(port, registers))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=folder / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    await runtime.start()
    link = next(a for a in runtime.adapters if a.name == "links").links["remote"]
    starts: list[float] = []
    durations: list[float] = []
    poll = link.poll

    async def timed_poll() -> None:  # the bench's own stopwatch around each poll
        started = time.monotonic()
        starts.append(started)
        await poll()
        durations.append(time.monotonic() - started)

    link.poll = timed_poll  # type: ignore[method-assign]
    try:
        await asyncio.sleep(1.0)  # settle after the start
        polls_before, requests_before, begun = link.polls, count(remote), time.monotonic()
        first = len(starts)
        await asyncio.sleep(seconds)
        polls, requests, elapsed = link.polls - polls_before, count(remote) - requests_before, time.monotonic() - begun
        bad = [tag.name for tag in runtime.db if tag.name.startswith("r") and tag.quality is not Quality.GOOD]
    finally:
        await runtime.stop()
    intervals = [(b - a) * 1000 for a, b in zip(starts[first:], starts[first + 1:])]
    taken = sorted(d * 1000 for d in durations[first:])
    per_poll = requests / max(polls, 1)
    print(f"{registers} registers, {link.describe()['requests_per_poll']} read requests per poll (groups of ≤ 125)")
    print(f"over {elapsed:.1f} s: {polls} polls ({polls / elapsed:.2f}/s), {requests} requests at the server: {per_poll:.2f} per poll")
    print(f"poll interval: mean {statistics.fmean(intervals):.1f} ms, p99 {sorted(intervals)[int(len(intervals) * 0.99)]:.1f} ms, "
          f"max {max(intervals):.1f} ms (period {PERIOD_MS:g} ms)")
    print(f"poll duration: median {statistics.median(taken):.2f} ms, p99 {taken[int(len(taken) * 0.99)]:.2f} ms, max {taken[-1]:.2f} ms")
    print(f"tags not GOOD at the end: {len(bad)}")
    met_requests = per_poll <= GOAL_REQUESTS
    met_interval = statistics.fmean(intervals) <= GOAL_INTERVAL_MS
    print(f"requests per poll ≤ {GOAL_REQUESTS}: {'met' if met_requests else 'GOAL MISSED'}; "
          f"mean interval ≤ {GOAL_INTERVAL_MS:g} ms: {'met' if met_interval else 'GOAL MISSED'}")
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {os.cpu_count()} CPUs")
    return 0 if met_requests and met_interval and not bad else 1


async def main(registers: int, seconds: float) -> int:
    remote = subprocess.Popen([sys.executable, __file__, "--serve", "--registers", str(registers)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        assert remote.stdout is not None
        port = int(remote.stdout.readline())
        with tempfile.TemporaryDirectory(prefix="links-bench-") as folder:
            return await measure(remote, port, registers, seconds, Path(folder))
    finally:
        assert remote.stdin is not None
        remote.stdin.close()
        try:
            remote.wait(5)
        except subprocess.TimeoutExpired:
            remote.kill()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--registers", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        asyncio.run(serve(args.registers))
    else:
        sys.exit(asyncio.run(main(args.registers, args.seconds)))
