"""1,000 tags bound to another controller's OPC UA server: how soon after the remote answers are they all GOOD?

The remote is asyncua's own `Server` in a separate process with 1,000 Int32 variables (folders
of 100). For each run a fresh runtime starts with a link binding 1,000 tags to them; the figure is
from the moment the remote answered (its session open: `OpcuaLink.session_at`) to the moment the
last of the 1,000 tags is GOOD with the remote's value in the tag database (the link reads their
types in one request, subscribes in one CreateMonitoredItems batch, takes the first notifications
in one batch; the journal is applied at the next 10 ms scan).

Goal (issue 26): ≤ 0.5 s (the median of the runs; the worst is printed too).

    .venv/bin/python bench/links_opcua_subscribe.py [--items 1000] [--runs 5]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

GOAL_SECONDS = 0.5
NAMESPACE = "urn:bench:remote"

async def serve(port: int, items: int) -> None:
    """The remote: asyncua's Server with `items` Int32 variables V0.. (value = index), until killed."""
    from asyncua import Server, ua

    server = Server()
    await server.init()
    server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/remote/")
    index = await server.register_namespace(NAMESPACE)
    folder = None
    for item in range(items):
        if item % 100 == 0:
            folder = await server.nodes.objects.add_folder(index, f"F{item // 100}")
        assert folder is not None
        await folder.add_variable(ua.NodeId(f"V{item}", index), f"V{item}", ua.Variant(item, ua.VariantType.Int32))
    async with server:
        print("ready", flush=True)
        # Until the bench ends: its end (even a kill) closes our stdin.
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)

def plant(port: int, items: int) -> str:
    lines = ["plant: {name: bench}", "links:",
             f"  remote: {{protocol: opcua, endpoint: 'opc.tcp://127.0.0.1:{port}/remote/', namespace: '{NAMESPACE}', period: 100ms, timeout: 5s}}",
             "tags:"]
    lines += [f"  v{i}: {{type: int32, initial: -1, link: {{name: remote, source: 'ns={{ns}};s=V{i}'}}}}" for i in range(items)]
    lines += ["tasks:", "  main: {interval: 10ms}", "servers:", "  opcua: {enabled: false}", "  modbus: {enabled: false}", "  hmi: {enabled: false}"]
    return "\n".join(lines) + "\n"

async def one_run(path: Path, items: int) -> tuple[float, float, float]:
    """(remote answered → all GOOD, of which answered → monitored items created, start → all GOOD) in seconds."""
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime
    from softplc.config import load_config
    from softplc.core.clock import RealClock
    from softplc.core.tags import Quality

    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=path.parent / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    good: set[str] = set()
    done = asyncio.Event()
    finished: list[float] = []

    def changed(tags: object) -> None:
        for tag in tags:  # type: ignore[attr-defined]
            if tag.name.startswith("v") and tag.quality is Quality.GOOD and tag.value == int(tag.name[1:]):
                good.add(tag.name)
        if len(good) == items and not done.is_set():
            finished.append(runtime.clock.now())
            done.set()

    runtime.db.on_change(changed)
    begun = runtime.clock.now()
    await runtime.start()
    try:
        try:
            await asyncio.wait_for(done.wait(), 60)
        except TimeoutError:
            raise SystemExit(f"only {len(good)} of {items} tags GOOD with their values after 60 s") from None
        link = next(a for a in runtime.adapters if a.name == "links").links["remote"]
        return finished[0] - link.session_at, link.subscribed_at - link.session_at, finished[0] - begun
    finally:
        await runtime.stop()

async def main(items: int, runs: int) -> int:

    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    remote = subprocess.Popen([sys.executable, __file__, "--serve", str(port), "--items", str(items)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        assert remote.stdout is not None
        if remote.stdout.readline().strip() != "ready":
            raise SystemExit("the remote server did not start")
        figures: list[tuple[float, float, float]] = []
        with tempfile.TemporaryDirectory(prefix="links-bench-") as folder:
            path = Path(folder) / "plant.yaml"
            path.write_text(plant(port, items))
            for run in range(runs):
                answered, subscribed, started = await one_run(path, items)
                figures.append((answered, subscribed, started))
                print(f"run {run + 1}: {items} items GOOD {answered * 1000:.0f} ms after the remote answered, of which "
                      f"{subscribed * 1000:.0f} ms until its CreateMonitoredItems answer ({started * 1000:.0f} ms after the "
                      "runtime's start began)", flush=True)
    finally:
        remote.kill()
        remote.wait()
    median = statistics.median(answered for answered, _, _ in figures)
    worst = max(answered for answered, _, _ in figures)
    verdict = "met" if median <= GOAL_SECONDS else "GOAL MISSED"
    print(f"\n{items} bound OPC UA items, remote answered → all GOOD: median {median * 1000:.0f} ms, worst {worst * 1000:.0f} ms "
          f"over {runs} runs (goal ≤ {GOAL_SECONDS * 1000:.0f} ms): {verdict}")
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {os.cpu_count()} CPUs")
    return 0 if verdict == "met" else 1

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--items", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--serve", type=int, metavar="PORT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        asyncio.run(serve(args.serve, args.items))
    else:
        sys.exit(asyncio.run(main(args.items, args.runs)))
