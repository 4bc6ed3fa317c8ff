"""The HMI under load: how late 5,000 tags changing at 10 Hz reach the wire, a Chromium page's DOM and
nine other WebSocket clients, what the 10 ms task's start latency and the HMI's CPU become.

The plant (made in a temporary folder): 5,000 float tags, each changed 10 times a second by ten
programs of a 10 ms task (each owns a tenth of the tags and changes them every 10th scan: 50,000
changes/s, spread so no scan is long), a `stamp` tag that program sets to the wall time of its
scan, a `probe` tag written over Modbus by this script at random moments (every 100-300 ms: a
sparse change, as an operator's), and a second 10 ms task of highest priority whose start
latency is measured. Watched by one Chromium page (a user view showing the probe and the stamp,
its live channel watching all 5,000 tags) and --clients more WebSocket clients in 3 other
processes, each subscribed to all of them. The runtime runs as `softplc run` in its own process
(HMI and Modbus on free ports, no OPC UA).

Two windows of --seconds each: without any client (baseline), then with them. Reported, each
apart so a slow browser on a busy machine is not blamed on the server, nor the other way round:
- **server side**: the runtime's own record (GET /api/diagnostics?since=T, softplc/adapters/hmi/delivery.py)
  of every frame sent to every client: its oldest value's commit → the frame handed to the socket;
- **wire**: probe written over Modbus → the frame carrying it received by the other clients,
  and the stamp's age when received (scan → another process read it);
- **page**: probe written → its text in the page's DOM (MutationObserver; the page's Date.now()
  is the wall clock this script and the runtime read), the stamp's age when shown, and frame
  received by the page → DOM;
- **rate**: per client, the values of each load tag received per second (the tags change 10
  times a second: every client should see min(rate, 10) of them, or be told it is thinned), the
  messages a second, and the "thinned" notices;
- the 10 ms task's start latency p99 and max (the runtime's own statistics), both windows;
- the runtime process's CPU in both windows (the difference is what the clients cost) and the
  HMI's own dispatch + encode time.

Goals (issue 23): server side p95 ≤ 20 ms; change → page DOM p95 ≤ 100 ms; every client ≥ 95 %
of the configured rate or told it is thinned; 10 ms task p99 start latency ≤ 1 ms; the clients
cost ≤ 25 % of a core. Each missed goal prints GOAL MISSED.

    .venv/bin/python bench/hmi_live.py                      # 30 s windows, 5,000 tags, 9 more clients, 10 updates/s
    .venv/bin/python bench/hmi_live.py --seconds 20 --rt-priority 50
    .venv/bin/python bench/hmi_live.py --runtime-path DIR   # the runtime of another checkout (before/after, same sitting)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from timing import load_average  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
PROGRAMS = '''
from softplc import InOut, Output, Param, Program


class Churn(Program):
    """Every 10th scan (at its `phase`), changes all of its values; the scan's wall time goes to `stamp`."""

    values = Output("load tags")
    stamp = Output("wall time of this scan, s", optional=True)
    phase = Param(0, "which of 10 scans changes the values")

    def setup(self):
        self.round = 0

    def scan(self):
        self.round += 1
        if self.round % 10 == self.phase:
            step = (self.round // 10) % 1000
            self.values = [step + index * 0.001 for index in range(len(self.values))]
        if self.stamp is not None:
            self.stamp = self.clock.wall()


class Beat(Program):
    count = InOut("scans")

    def scan(self):
        self.count = (self.count + 1) % 2**32
'''


def load_names(tags: int) -> list[str]:
    width = max(2, len(str(tags)))  # as a template's `count:` numbers its instances
    return [f"l{index:0{width}d}_v" for index in range(1, tags + 1)]


def make_plant(folder: Path, tags: int, rate: float, show: bool = False) -> Path:
    names = load_names(tags)
    columns = 50
    texts = []
    for index in range(tags if show else 0):
        x, y = 10 + (index % columns) * 38, 40 + (index // columns) * 9
        texts.append(f'<text id="t{index}" x="{x}" y="{y}" font-size="7">0</text>')
    height = 60 + (len(texts) // columns + 1) * 9
    (folder / "load.svg").write_text(
        f'<svg xmlns="http://www.w3.org/2000/svg" width="1920" height="{height}" viewBox="0 0 1920 {height}">'
        '<text id="probe_text" x="10" y="14" font-size="12">0</text><text id="stamp_text" x="200" y="14" font-size="12">0</text>'
        + "".join(texts) + "</svg>")
    (folder / "load_programs.py").write_text(PROGRAMS)
    bindings = "\n".join(f"        t{index}: {{text: {name}}}" for index, name in enumerate(names) if show)
    # Ten programs of a tenth of the tags each, one of them changing its values per 10 ms scan:
    # every tag changes 10 times a second, and no scan commits more than a tenth of them.
    share = -(-tags // 10)
    churners = "\n".join(
        f"      - {{name: churn{phase}, program: load_programs.py:Churn, params: {{phase: {phase}}}, "
        f"bind: {{values: [{', '.join(names[phase * share:(phase + 1) * share])}]{', stamp: stamp' if phase == 0 else ''}}}}}"
        for phase in range(10) if names[phase * share:(phase + 1) * share])
    (folder / "tagdb.yaml").write_text(f"""
version: 1
plant: {{name: hmi-bench}}
templates:
  load:
    group: Load
    count: {tags}
    prefix: l
    tags: {{v: {{type: float64}}}}
tags:
  probe: {{type: int16}}
  stamp: {{type: float64, access: ro}}
  beat:  {{type: uint32, access: ro}}
tasks:
  fast:
    interval: 10ms
    priority: 0
    programs: [{{name: beat, program: load_programs.py:Beat, bind: {{count: beat}}}}]
  load:
    interval: 10ms
    priority: 5
    programs:
{churners}
servers:
  opcua: {{enabled: false}}
  modbus: {{enabled: true, host: 127.0.0.1, port: 0}}
  hmi: {{host: 127.0.0.1, port: 0, max_update_rate: {rate}}}
hmi:
  views:
    load:
      svg: load.svg
      bindings:
        probe_text: {{text: probe}}
        stamp_text: {{text: {{tag: stamp, decimals: 3}}}}
{bindings}
""")
    return folder / "tagdb.yaml"


# -- the other WebSocket clients (run as child processes of this script) ---------------------------

PROBE = re.compile(r'"probe":(\d+)')
STAMP = re.compile(r'"stamp":([0-9.]+)')


async def ws_clients(url: str, items_file: str, count: int, seconds: float) -> None:
    """`count` clients subscribed to every item, until the file `items_file` + ".stop" exists (at most `seconds`);
    prints per client: per-second figures, probe sightings, stamp ages."""
    import aiohttp

    items = json.loads(Path(items_file).read_text())
    stop = Path(items_file + ".stop")

    async def one() -> dict[str, object]:
        seconds_seen: dict[int, list[int]] = {}  # wall second → [messages, load values, bytes]
        probes: dict[str, float] = {}  # probe value → wall time first received
        stamps: list[tuple[float, float]] = []  # (wall time received, age in ms)
        thinned = 0
        async with aiohttp.ClientSession() as session, session.ws_connect(url, max_msg_size=0) as ws:
            await ws.send_json({"type": "subscribe", "items": items})
            deadline, next_look = time.monotonic() + seconds, 0.0
            while time.monotonic() < deadline:
                if time.monotonic() > next_look:  # the measurement is over
                    if stop.exists():
                        break
                    next_look = time.monotonic() + 0.5
                try:
                    message = await ws.receive(timeout=0.5)
                except asyncio.TimeoutError:
                    continue
                if message.type is not aiohttp.WSMsgType.TEXT:
                    break
                now, data = time.time(), message.data
                if data.startswith('{"type":"update"'):
                    figures = seconds_seen.setdefault(int(now), [0, 0, 0])
                    figures[0] += 1
                    start = data.index('"values":{')
                    figures[1] += data.count('"l', start, data.index("}", start))  # the load tags (l0001_v ...) among the values
                    figures[2] += len(data)
                    if (found := PROBE.search(data)) and found.group(1) not in probes:
                        probes[found.group(1)] = now
                    if found := STAMP.search(data):
                        stamps.append((now, (now - float(found.group(1))) * 1000))
                elif data.startswith('{"type":"ping"'):
                    await ws.send_str('{"type":"pong"}')
                elif data.startswith('{"type":"thinned"'):
                    thinned += 1
        return {"seconds": seconds_seen, "probes": probes, "stamps": stamps, "thinned": thinned}

    print(json.dumps(await asyncio.gather(*(one() for _ in range(count)))))


# -- the measurement ------------------------------------------------------------------------------

def cpu_seconds(pid: int) -> tuple[float, float]:
    """(user, system) CPU seconds of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    tick = os.sysconf("SC_CLK_TCK")
    return int(fields[11]) / tick, int(fields[12]) / tick


def percentiles(values: list[float]) -> str:
    if not values:
        return "no samples"
    data = np.array(values)
    return f"p50 {np.percentile(data, 50):.1f} / p95 {np.percentile(data, 95):.1f} / max {data.max():.1f} ms (n={len(data)})"


def p95(values: list[float]) -> float:
    return float(np.percentile(values, 95)) if values else float("inf")


PAGE_RECORDER = """() => {
    // Frames as the page's live channel receives them (before parsing), and the DOM changes of probe and
    // stamp, at Date.now(): the wall clock this script and the runtime read too.
    window.__probe = []; window.__stamp = []; window.__frameProbe = {}; window.__frameStamp = {};
    window.__thinned = 0; window.__values = 0;
    const live = window.softplcHmi.live;
    const receive = live._receive.bind(live);
    live._receive = (text) => {
        const at = Date.now();
        const probe = /"probe":(\\d+)/.exec(text), stamp = /"stamp":([0-9.]+)/.exec(text);
        if (probe && !(probe[1] in window.__frameProbe)) window.__frameProbe[probe[1]] = at;
        if (stamp) window.__frameStamp[Number(stamp[1]).toFixed(3)] = at;
        if (text.startsWith('{"type":"thinned"')) window.__thinned += 1;
        receive(text);
    };
    for (const [id, list] of [['probe_text', window.__probe], ['stamp_text', window.__stamp]]) {
        const node = document.getElementById(id);
        new MutationObserver(() => list.push([node.textContent, Date.now()]))
            .observe(node, {subtree: true, childList: true, characterData: true});
    }
}"""


async def main(args: argparse.Namespace) -> None:
    import aiohttp
    from playwright.async_api import async_playwright
    from pymodbus.client import AsyncModbusTcpClient

    from softplc.adapters.modbus.address_map import build_address_map
    from softplc.adapters.modbus.settings import ModbusSettings
    from softplc.config import load_config

    folder = Path(tempfile.mkdtemp(prefix="hmi-bench-"))
    config_path = make_plant(folder, args.tags, args.rate, show=args.page == 'show')
    command = [sys.executable, "-m", "softplc.app.cli", "run", str(config_path), "--no-status", "--state-dir", str(folder / "state")]
    if args.rt_priority:
        command += ["--rt-priority", str(args.rt_priority)]
    runtime_path = Path(args.runtime_path).resolve() if args.runtime_path else REPO
    runtime = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=folder, env={**os.environ, "PYTHONPATH": str(runtime_path)})
    url = modbus_port = None
    started = time.monotonic()
    while (url is None or modbus_port is None) and time.monotonic() - started < 120:
        line = runtime.stderr.readline()
        if not line:
            raise SystemExit("the runtime ended before serving")
        if match := re.search(r"HMI on (http://\S+)", line):
            url = match.group(1)
        if match := re.search(r"Modbus TCP on 127.0.0.1:(\d+)", line):
            modbus_port = int(match.group(1))
    config = load_config(config_path)
    address_map = build_address_map(config, ModbusSettings.from_servers(config.servers))
    probe_address = address_map.by_tag["probe"].address
    reset_address = address_map.by_tag["_sys.reset_stats"].address
    modbus = AsyncModbusTcpClient("127.0.0.1", port=modbus_port, timeout=2, retries=0)
    await modbus.connect()
    http = aiohttp.ClientSession()

    async def figures() -> dict[str, float]:
        names = ",".join(f"_sys.fast.latency_ms_{stat}" for stat in ("p99", "max", "mean")) + ",_sys.fast.cycles,_sys.fast.overruns,_sys.load.cycles"
        async with http.get(f"{url}api/tags?names={names}") as response:
            found = {tag["name"]: tag["value"] for tag in (await response.json())["tags"]}
        result = {name.split(".")[-1].replace("latency_ms_", ""): value for name, value in found.items() if name.startswith("_sys.fast.")}
        result["load_cycles"] = found["_sys.load.cycles"]
        return result

    async def diagnostics(since: float = 0.0) -> dict[str, object]:
        async with http.get(f"{url}api/diagnostics?since={since}") as response:
            return (await response.json())["live"]

    async def window(seconds: float, probe: object | None = None) -> dict[str, object]:
        await modbus.write_coil(reset_address, True)
        await asyncio.sleep(0.7)  # the reset is executed by the housekeeping within 0.5 s
        cpu0, wall0, since, hub0 = cpu_seconds(runtime.pid), time.monotonic(), time.monotonic(), await diagnostics()
        start = time.time()
        if probe is not None:
            await probe(seconds)  # type: ignore[operator]
        else:
            await asyncio.sleep(seconds)
        cpu1, wall1, hub1 = cpu_seconds(runtime.pid), time.monotonic(), await diagnostics(since)
        end = time.time()
        await asyncio.sleep(0.6)  # statistics are published every 0.5 s
        result: dict[str, object] = dict(await figures())
        elapsed = wall1 - wall0
        result.update(cpu=(sum(cpu1) - sum(cpu0)) / elapsed, system=(cpu1[1] - cpu0[1]) / elapsed, start=start, end=end,
                      delivery=hub1.get("delivery"),
                      hmi_work=((hub1["encode_seconds"] - hub0["encode_seconds"]) + (hub1["dispatch_seconds"] - hub0["dispatch_seconds"])) / elapsed,
                      encode=(hub1["encode_seconds"] - hub0["encode_seconds"]) / elapsed,
                      messages=(hub1["messages_encoded"] - hub0["messages_encoded"]) / elapsed,
                      dropped=hub1["dropped"] - hub0["dropped"])
        return result

    try:
        await asyncio.sleep(2.0)  # start-up settles
        print(f"runtime on {url} ({'this checkout' if runtime_path == REPO else runtime_path}), {args.tags} tags each changing "
              f"10 times a second; load average {load_average()}", flush=True)
        baseline = await window(args.seconds)
        print(f"without clients: runtime CPU {baseline['cpu'] * 100:.1f} % of a core, 10 ms task start latency "
              f"p99 {baseline['p99']:.3f} ms, max {baseline['max']:.3f} ms ({baseline['cycles']} cycles)", flush=True)

        items = load_names(args.tags) + ["probe", "stamp"]
        items_file = folder / "items.json"
        items_file.write_text(json.dumps(items))
        total = args.seconds + 300  # at most: the clients stop when the window is over (items.json.stop)
        per_process = [args.clients // 3 + (1 if index < args.clients % 3 else 0) for index in range(3)]
        clients = [subprocess.Popen([sys.executable, __file__, "--ws-clients", str(count), "--url", url.replace("http", "ws") + "api/live",
                                     "--items-file", str(items_file), "--seconds", str(total)], stdout=subprocess.PIPE, text=True)
                   for count in per_process if count]
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = await browser.new_page(viewport={"width": 1280, "height": 800})
            await page.goto(url + "#/view/load")
            await page.wait_for_selector("main[data-ready='1']", timeout=60000)
            if args.page == "watch":
                # The page's live channel watches every tag (a page's watch, as the pages use), showing only probe and stamp.
                await page.evaluate("""(names) => { window.__updates = 0; window.softplcHmi.live.watch(names, (changed) => { window.__updates += changed.length; }); }""",
                                    items)
                await page.wait_for_function("(count) => window.__updates >= count", arg=args.tags, timeout=60000)
            await page.evaluate(PAGE_RECORDER)
            waited = time.monotonic()
            while (await diagnostics())["clients"] < args.clients + 1 and time.monotonic() - waited < 120:
                await asyncio.sleep(0.5)  # every client connected before the window opens
            await asyncio.sleep(2.0)
            written: dict[int, float] = {}
            page_values: list[float] = []

            async def probe(seconds: float) -> None:
                value, deadline = 0, time.monotonic() + seconds
                page_values.append(await page.evaluate("() => window.__updates || 0"))
                while time.monotonic() < deadline:
                    await asyncio.sleep(random.uniform(0.1, 0.3))
                    value = value % 30000 + 1
                    written[value] = time.time() * 1000
                    await modbus.write_register(probe_address, value)
                page_values.append(await page.evaluate("() => window.__updates || 0"))

            loaded = await window(args.seconds, probe)
            Path(str(items_file) + ".stop").touch()
            seen = await page.evaluate("() => [window.__probe, window.__stamp, window.__frameProbe, window.__frameStamp, window.__thinned]")
            probe_seen, stamp_seen, frame_probe, frame_stamp, page_thinned = seen
            await browser.close()
        reports = [client for process in clients for client in json.loads(process.communicate(timeout=total + 30)[0])]
        report(args, baseline, loaded, reports, written, probe_seen, stamp_seen, frame_probe, frame_stamp, page_thinned, page_values)
    finally:
        await http.close()
        modbus.close()
        runtime.terminate()
        try:
            runtime.wait(30)
        except subprocess.TimeoutExpired:
            runtime.kill()
            runtime.wait()
        shutil.rmtree(folder, ignore_errors=True)


def report(args: argparse.Namespace, baseline: dict, loaded: dict, reports: list[dict], written: dict[int, float],
           probe_seen: list, stamp_seen: list, frame_probe: dict, frame_stamp: dict, page_thinned: int, page_values: list[float]) -> None:
    """Print the figures and a line per goal."""
    start, end = loaded["start"], loaded["end"]
    seconds = end - start
    # Page: probe written → DOM, frame received → DOM; the stamp's age when shown.
    probe_dom: dict[int, float] = {}
    for text, at in probe_seen:
        if text.isdigit() and int(text) not in probe_dom:
            probe_dom[int(text)] = at
    write_to_dom = [probe_dom[value] - at for value, at in written.items() if value in probe_dom]
    frame_to_dom = [shown - frame_probe[str(value)] for value, shown in probe_dom.items() if str(value) in frame_probe]
    stamp_to_dom = [at - float(text) * 1000 for text, at in stamp_seen if re.fullmatch(r"\d+\.\d+", text)]
    stamp_frame_to_dom = [at - frame_stamp[text] for text, at in stamp_seen if text in frame_stamp]
    # Wire: the other clients' first sight of each probe value, and the stamp's age at receipt.
    write_to_wire = [float(seen_at) * 1000 - written[int(value)] for client in reports for value, seen_at in client["probes"].items()
                     if int(value) in written]
    stamp_wire = [age for client in reports for at, age in client["stamps"] if start <= at <= end]
    # Rate: the load tags' values each client received per tag and second, inside the window's whole seconds.
    inside = range(int(start) + 1, int(end))
    produced = loaded["load_cycles"] / 10 / seconds  # each tag changes every 10th scan of the load task (10/s when none is skipped)
    expected = min(args.rate, produced)
    rates = []
    for client in reports:
        buckets = [client["seconds"].get(str(second), [0, 0, 0]) for second in inside]
        rates.append((sum(b[1] for b in buckets) / args.tags / max(len(buckets), 1), sum(b[0] for b in buckets) / max(len(buckets), 1),
                      client["thinned"]))
    page_rate = (page_values[1] - page_values[0]) / args.tags / seconds if len(page_values) == 2 and args.page == "watch" else None
    delivery = loaded.get("delivery") or {}
    megabytes = sum(sum(client["seconds"].get(str(second), [0, 0, 0])[2] for second in inside) for client in reports) / 1e6 / max(len(inside), 1)
    missed = len(written) - len(write_to_dom)

    print(f"with 1 Chromium page ({args.page}) + {args.clients} WebSocket clients, {args.rate:g} updates/s per value:")
    if delivery.get("frames"):
        print(f"  server side, change committed → frame handed to the socket: p50 {delivery['p50_ms']} / p95 {delivery['p95_ms']} / "
              f"p99 {delivery['p99_ms']} / max {delivery['max_ms']} ms ({delivery['frames']} frames to all clients)")
    else:
        print("  server side: not measured (this runtime keeps no delivery record)")
    print(f"  wire, Modbus write → frame received by another client: {percentiles(write_to_wire)}")
    print(f"  wire, program scan → frame received by another client (age of the stamp): {percentiles(stamp_wire)}")
    print(f"  page, Modbus write → DOM: {percentiles(write_to_dom)}{f'; {missed} probe values never shown (superseded)' if missed else ''}")
    print(f"  page, program scan → DOM (age of the shown stamp): {percentiles(stamp_to_dom)}")
    print(f"  page, frame received → DOM: probe {percentiles(frame_to_dom)}; stamp {percentiles(stamp_frame_to_dom)}")
    low, high = (min(r[0] for r in rates), max(r[0] for r in rates)) if rates else (0.0, 0.0)
    print(f"  other clients: {low:.2f}..{high:.2f} values of each tag a second (expected {expected:.2f}), "
          f"{min((r[1] for r in rates), default=0):.0f}..{max((r[1] for r in rates), default=0):.0f} messages a second, "
          f"{sum(r[2] for r in rates)} 'thinned' notices; {megabytes:.1f} MB/s together; the tags changed {produced:.2f} times a second"
          + (f"; the page {page_rate:.2f} values of each tag a second, {page_thinned} 'thinned' notices" if page_rate is not None else ""))
    print(f"  10 ms task start latency: p99 {loaded['p99']:.3f} ms, max {loaded['max']:.3f} ms, mean {loaded['mean']:.3f} ms "
          f"({loaded['cycles']} cycles, {loaded['overruns']} overruns)")
    print(f"  runtime CPU {loaded['cpu'] * 100:.1f} % of a core, {loaded['system'] * 100:.1f} % of it in the kernel (baseline "
          f"{baseline['cpu'] * 100:.1f} %, kernel {baseline['system'] * 100:.1f} %: the clients cost "
          f"{(loaded['cpu'] - baseline['cpu']) * 100:.1f} %); HMI dispatch + encode {loaded['hmi_work'] * 100:.1f} % "
          f"(encode {loaded['encode'] * 100:.1f} %: {loaded['messages']:.0f} messages/s; {loaded['dropped']} clients dropped)")
    print(f"  load average {load_average()} (2 cores shared)")
    clients_cost = loaded["cpu"] - baseline["cpu"]
    everyone = [(rate, thinned) for rate, _, thinned in rates] + ([(page_rate, page_thinned)] if page_rate is not None else [])
    starved = [rate for rate, thinned in everyone if rate < 0.95 * expected and not thinned]
    server_p95 = delivery.get("p95_ms", float("inf")) if delivery.get("frames") else float("inf")
    for goal, met in ((f"server side change → frame sent p95 ≤ 20 ms ({server_p95:.1f} ms)", server_p95 <= 20),
                      (f"change → page DOM p95 ≤ 100 ms (Modbus write {p95(write_to_dom):.0f} ms)", p95(write_to_dom) <= 100),
                      (f"change → page DOM p95 ≤ 100 ms (program scan {p95(stamp_to_dom):.0f} ms)", p95(stamp_to_dom) <= 100),
                      (f"every client ≥ 95 % of {expected:.2f} values a second or told it is thinned ({len(starved)} of {len(everyone)} "
                       f"neither)", not starved and bool(everyone)),
                      (f"10 ms task start latency p99 ≤ 1 ms ({loaded['p99']:.3f} ms)", loaded["p99"] <= 1.0),
                      (f"HMI ≤ 25 % of a core ({clients_cost * 100:.1f} % more CPU with the clients)", clients_cost <= 0.25)):
        print(f"  {'goal met' if met else 'GOAL MISSED'}: {goal}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--tags", type=int, default=5000)
    parser.add_argument("--clients", type=int, default=9)
    parser.add_argument("--rate", type=float, default=10.0, help="servers.hmi.max_update_rate")
    parser.add_argument("--rt-priority", type=int, default=0)
    parser.add_argument("--page", choices=("watch", "show"), default="watch",
                        help="watch: the page watches all tags and shows the probe (default); show: the view shows all of them")
    parser.add_argument("--runtime-path", help="run the runtime from this checkout (its softplc/ and hmi/), e.g. an older commit's")
    parser.add_argument("--ws-clients", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--url", help=argparse.SUPPRESS)
    parser.add_argument("--items-file", help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.ws_clients:
        asyncio.run(ws_clients(arguments.url, arguments.items_file, arguments.ws_clients, arguments.seconds))
    else:
        asyncio.run(main(arguments))
