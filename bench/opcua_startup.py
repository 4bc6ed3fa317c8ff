"""OPC UA start-up: time until every tag is served, and memory, for plants of 1k, 10k and 50k tags.

For each size `softplc run` is launched on a generated plant (folders of 50 tags, a third of
them analog with EURange and EngineeringUnits) and measured:

- ready: the adapter's own figure, from Runtime.start() calling it to listening with every node
  in place (the log line "OPC UA serving ... ready in X s");
- launch→serving: process launch to the "serving:" line (Python imports and config load included);
- first read: an asyncua client connects and reads the last tag, right after "serving:";
- RSS of the server process, and the same plant's RSS with --no-opcua (the OPC UA share).

Goal (issue 3): 10k tags served within 3 s of start (the "ready" figure).

    .venv/bin/python bench/opcua_startup.py [--sizes 1000 10000 50000]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from asyncua import Client, ua  # noqa: E402
from opcua_common import goal, plant_yaml, start_server  # noqa: E402

GOAL_SECONDS = 3.0


async def first_read(endpoint: str, tag: str) -> float:
    started = time.perf_counter()
    async with Client(endpoint, timeout=30) as client:
        ns = await client.get_namespace_index("urn:softplc:tags")
        await client.get_node(ua.NodeId(tag, ns)).read_value()
    return time.perf_counter() - started


def measure(size: int, folder: Path) -> dict[str, float]:
    yaml_text = plant_yaml(size, changing=10)
    baseline = start_server(folder / "baseline", yaml_text, opcua=False)
    time.sleep(1.0)
    baseline_rss = baseline.rss_mb()
    baseline.stop()
    server = start_server(folder / "served", yaml_text)
    try:
        instances = size // 50
        last_tag = f"c{instances:0{max(2, len(str(instances)))}d}_v49"
        read_seconds = asyncio.run(first_read(server.endpoint, last_tag))
        time.sleep(1.0)
        rss = server.rss_mb()
    finally:
        server.stop()
    return {"ready": server.ready_seconds, "launch": server.launch_to_serving, "read": read_seconds, "rss": rss, "baseline_rss": baseline_rss}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 50000])
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            figures = measure(size, Path(tmp) / str(size))
            rows.append((size, figures))
            print(f"{size:>6} tags: ready {figures['ready']:.2f} s, launch→serving {figures['launch']:.2f} s, "
                  f"first read {figures['read'] * 1e3:.0f} ms, RSS {figures['rss']:.0f} MB "
                  f"(without OPC UA {figures['baseline_rss']:.0f} MB)", flush=True)
    print("\n| tags | ready (adapter start → listening) | launch → serving | first client read | RSS | RSS without OPC UA |")
    print("|---:|---:|---:|---:|---:|---:|")
    for size, f in rows:
        print(f"| {size:,} | {f['ready']:.2f} s | {f['launch']:.2f} s | {f['read'] * 1e3:.0f} ms | {f['rss']:.0f} MB | {f['baseline_rss']:.0f} MB |")
    ok = True
    for size, f in rows:
        if size == 10000:
            ok = goal("10k tags ready (s)", f["ready"], GOAL_SECONDS) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
