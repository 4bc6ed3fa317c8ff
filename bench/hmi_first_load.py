"""First load of the HMI's plant overview in Chromium: from navigation to the mimic drawn with live values.

Runs the default plant (tagdb.yaml: map, three robots, two tasks) with `softplc run` on free
ports, then opens the overview --loads times, each in a fresh browser context (no cache, no
cookies), and reads the page's own clock: DOMContentLoaded, the load event, and `ready` — the
moment the overview has drawn the floor, the stations and robots with the values of the first
snapshot (`main[data-ready]`). Prints p50 and max of each, and what was transferred.

Goal (issue 15): first load ≤ 1 s.

    .venv/bin/python bench/hmi_first_load.py [--loads 10] [--page overview]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "bench"))

from timing import load_average  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


async def main(args: argparse.Namespace) -> None:
    from playwright.async_api import async_playwright

    state = Path(tempfile.mkdtemp(prefix="hmi-load-"))
    runtime = subprocess.Popen([sys.executable, "-m", "softplc.app.cli", "run", str(REPO / "tagdb.yaml"), "--no-status", "--state-dir", str(state),
                                "--opcua-endpoint", "opc.tcp://127.0.0.1:0/softplc/", "--modbus-port", "0", "--hmi-port", "0"],
                               stderr=subprocess.PIPE, text=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    url = None
    deadline = time.monotonic() + 120
    while url is None and time.monotonic() < deadline:
        line = runtime.stderr.readline()
        if not line:
            raise SystemExit("the runtime ended before serving")
        if match := re.search(r"HMI on (http://\S+)", line):
            url = match.group(1)
    try:
        await asyncio.sleep(3.0)  # robots under way, planning worker up
        rows = []
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            for _ in range(args.loads):
                context = await browser.new_context(viewport={"width": 1280, "height": 800})
                page = await context.new_page()
                await page.goto(f"{url}#/{args.page}")
                await page.wait_for_selector("main[data-ready='1']", timeout=30000)
                ready = await page.evaluate("() => performance.now()")
                timing = await page.evaluate("""() => { const n = performance.getEntriesByType('navigation')[0];
                    const bytes = performance.getEntriesByType('resource').reduce((sum, r) => sum + (r.transferSize || 0), n.transferSize || 0);
                    return [n.domContentLoadedEventEnd, n.loadEventEnd, bytes, performance.getEntriesByType('resource').length + 1]; }""")
                rows.append((timing[0], timing[1], ready, timing[2], timing[3]))
                await context.close()
            await browser.close()
        data = np.array(rows)
        print(f"{args.page} of the default plant, {args.loads} cold loads in fresh contexts (1280x800), load average {load_average()}:")
        for column, label in ((0, "DOMContentLoaded"), (1, "load event"), (2, "ready (mimic drawn with live values)")):
            print(f"  {label}: p50 {np.percentile(data[:, column], 50):.0f} ms, max {data[:, column].max():.0f} ms")
        print(f"  {int(data[0, 4])} requests, {data[0, 3] / 1024:.0f} KiB transferred")
        ready = float(np.percentile(data[:, 2], 50))
        print(f"  {'goal met' if ready <= 1000 else 'GOAL MISSED'}: first load ≤ 1 s (ready p50 {ready:.0f} ms, max {data[:, 2].max():.0f} ms)")
    finally:
        runtime.terminate()
        try:
            runtime.wait(30)
        except subprocess.TimeoutExpired:
            runtime.kill()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--loads", type=int, default=10)
    parser.add_argument("--page", default="overview")
    asyncio.run(main(parser.parse_args()))
