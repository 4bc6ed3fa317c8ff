"""The VDA 5050 master control with 100 (or 500) vda-5050-lib virtual vehicles on Debian's mosquitto.

A plant with a 10 ms task (the start-latency probe) and N `driver: vda5050` robots on a grid roadmap runs
in this process (the real clock); the vehicles run in Node processes (tests/vda5050_node/vehicles.js,
100 per process, state at least every second). Each free vehicle gets a random goal node, for
`--seconds`. An independent MQTT client records every order and state: the latency of an order is from
the order reaching that client to the first state with its orderId and orderUpdateId reaching it (the
vehicle's acknowledgement), both seen by the same client; every order and instant action is checked
against the closed JSON Schemas. Then: one vehicle (a process of its own) is frozen with SIGSTOP — how
long until the master flags it (its state interval is 1 s) — and the broker is restarted — how long from
its return until the master has subscribed again and hears the vehicles.

Goals (issue 24): order → acknowledging state p95 ≤ 100 ms at 100 vehicles; the 10 ms task's p99 start
latency ≤ 1 ms meanwhile; 0 schema violations; re-subscribed ≤ 5 s after the broker returns; a lost
vehicle flagged ≤ 2× its state interval.

    .venv/bin/python bench/vda5050_fleet.py [--vehicles 100] [--seconds 60]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import shutil
import signal
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(REPO), str(REPO / "tests"), str(REPO / "bench")]

from mosquitto_server import MosquittoServer  # noqa: E402
from timing import load_average  # noqa: E402

from softplc.app.adapters import build_adapters  # noqa: E402
from softplc.app.runtime import Runtime  # noqa: E402
from softplc.config import load_config  # noqa: E402
from softplc.core.clock import RealClock  # noqa: E402
from softplc.protocols.mqtt import MqttConnection  # noqa: E402
from softplc.protocols.mqtt_settings import MqttSettings  # noqa: E402
from softplc.protocols.vda5050.validation import problems  # noqa: E402

NODE_DIR = REPO / "tests" / "vda5050_node"
SPACING = 2.0
STATE_INTERVAL = 1.0  # s: each vehicle's state at least this often
PER_PROCESS = 100


def write_plant(directory: Path, vehicles: int, url: str, rng: random.Random) -> list[tuple[str, float, float]]:
    side = int(np.ceil(np.sqrt(vehicles * 2.5)))
    nodes = [(f"n{c}_{r}", c * SPACING + 1, r * SPACING + 1) for c in range(side) for r in range(side)]
    lanes = [(f"n{c}_{r}", f"n{c + 1}_{r}") for c in range(side - 1) for r in range(side)]
    lanes += [(f"n{c}_{r}", f"n{c}_{r + 1}") for c in range(side) for r in range(side - 1)]
    (directory / "roadmap.yaml").write_text("roadmap:\n  map_id: grid\n  deviation: 0.3\n  waypoints:\n" + "".join(
        f"    - {{id: {name}, x: {x}, y: {y}}}\n" for name, x, y in nodes) + "  lanes:\n" + "".join(
        f"    - {{from: {a}, to: {b}}}\n" for a, b in lanes))
    starts = rng.sample(nodes, vehicles + 1)
    (directory / "robots.yaml").write_text("robots:\n" + "".join(
        f"  - {{id: v{index:03d}, driver: vda5050, vda5050: {{manufacturer: bench, serial_number: s{index:03d}, "
        f"instant_actions_key: instantActions}}, length_mm: 500, width_mm: 500, height_mm: 500, load_capacity: 1, "
        f"max_linear_speed: 2, max_angular_speed: 1, start: {{x: {x}, y: {y}}}}}\n" for index, (_, x, y) in enumerate(starts)))
    (directory / "tagdb.yaml").write_text(textwrap.dedent(f"""\
        version: 1
        plant: {{name: vda5050-bench}}
        tags:
          items: {{type: uint16}}
          capacity: {{type: uint16, initial: 100}}
          rate: {{type: float32, initial: 30}}
          level: {{type: float32}}
        templates:
          robot:
            instances_from: {{file: robots.yaml, initial: {{xpos: start.x, ypos: start.y, xgoal: start.x, ygoal: start.y}}}}
            tags:
              xpos: {{type: float64, access: ro}}
              ypos: {{type: float64, access: ro}}
              heading: {{type: float64, access: ro}}
              speed: {{type: float64, access: ro}}
              navstate: {{type: string, access: ro}}
              navreason: {{type: string, access: ro}}
              route: {{type: string, access: ro}}
              status: {{type: bool}}
              xgoal: {{type: float64}}
              ygoal: {{type: float64}}
              online: {{type: bool, access: ro}}
        tasks:
          fast:
            interval: 10ms
            programs:
              - name: probe
                program: programs.buffer_filler:InputBufferFiller
                bind: {{items: items, capacity: capacity, fill_rate: rate, level: level}}
        fleet: {{enabled: false, robots: robots.yaml, map: {REPO / "robots" / "maps" / "factory.yaml"}}}
        mqtt: {{url: "{url}", keepalive: 5s}}
        vda5050: {{roadmap: roadmap.yaml, lost_after: {2 * STATE_INTERVAL - 0.1:g}s, ack_timeout: 1s, tick: 50ms}}
        servers: {{opcua: {{enabled: false}}, modbus: {{enabled: false}}, hmi: {{enabled: false}}}}
        """))
    return starts


class Recorder:
    """Orders and states as an independent client sees them."""

    def __init__(self, port: int) -> None:
        self.sent: dict[tuple[str, int], float] = {}
        self.latencies: list[float] = []
        self.violations: list[str] = []
        self.orders = 0
        self.states_after: dict[str, float] = {}
        self.connection = MqttConnection(MqttSettings(port=port, client_id="bench"), "recorder", RealClock(), max_payload=10**7)
        self.connection.subscribe("uagv/v2/+/+/order", self._order)
        self.connection.subscribe("uagv/v2/+/+/instantActions", self._instant)
        self.connection.subscribe("uagv/v2/+/+/state", self._state)

    def _order(self, topic: str, payload: bytes, retained: bool) -> None:
        message = json.loads(payload)
        self.orders += 1
        self.violations += problems("order", "2.0", message)
        self.sent.setdefault((message["orderId"], message["orderUpdateId"]), time.monotonic())

    def _instant(self, topic: str, payload: bytes, retained: bool) -> None:
        message = json.loads(payload)
        if "instantActions" in message:  # vda-5050-lib's key, set by the master on purpose after its own check
            message["actions"] = message.pop("instantActions")
        self.violations += problems("instantActions", "2.0", message)

    def _state(self, topic: str, payload: bytes, retained: bool) -> None:
        message = json.loads(payload)
        key = (message.get("orderId"), message.get("orderUpdateId"))
        sent = self.sent.pop(key, None)
        if sent is not None:
            self.latencies.append(time.monotonic() - sent)


async def vehicles_process(port: int, vehicles: list[dict], **options: object) -> asyncio.subprocess.Process:
    config = {"broker": f"mqtt://127.0.0.1:{port}", "vehicles": vehicles, "heartbeat": 5, "stateInterval": int(STATE_INTERVAL * 1000),
              "speed": 2.0, "mapId": "grid", **options}
    process = await asyncio.create_subprocess_exec("node", str(NODE_DIR / "vehicles.js"), json.dumps(config), cwd=NODE_DIR,
                                                   stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT)
    assert process.stdout is not None
    line = await asyncio.wait_for(process.stdout.readline(), 120)
    if b'"ready"' not in line:
        raise SystemExit(f"vehicles.js did not start: {line!r}")
    return process


async def until(condition, timeout: float) -> float | None:
    started = time.monotonic()
    while not condition():
        if time.monotonic() - started > timeout:
            return None
        await asyncio.sleep(0.01)
    return time.monotonic() - started


async def run(args: argparse.Namespace) -> dict[str, float]:
    rng = random.Random(args.seed)
    broker = MosquittoServer(extra="max_queued_messages 100000\n")
    broker.start()
    directory = Path(tempfile.mkdtemp(prefix="vda5050-fleet-"))
    starts = write_plant(directory, args.vehicles, broker.url, rng)
    config = load_config(directory / "tagdb.yaml")
    runtime = Runtime(config, RealClock(), state_dir=directory / "state", retain=False)
    for item in build_adapters(config, None):
        runtime.add_adapter(item)
    master = next(item for item in runtime.adapters if item.name == "vda5050")
    recorder = Recorder(broker.port)
    recording = asyncio.ensure_future(recorder.connection.run())
    processes = []
    result: dict[str, float] = {}
    await runtime.start()
    db = runtime.db
    try:
        fleet = [{"manufacturer": "bench", "serialNumber": f"s{index:03d}", "x": x, "y": y, "lastNodeId": name}
                 for index, (name, x, y) in enumerate(starts)]
        for first in range(0, args.vehicles, PER_PROCESS):
            processes.append(await vehicles_process(broker.port, fleet[first: min(first + PER_PROCESS, args.vehicles)]))
        frozen = await vehicles_process(broker.port, fleet[args.vehicles:])  # the one to freeze, alone in its process
        ids = [f"v{index:03d}" for index in range(args.vehicles)]
        ready = await until(lambda: all(db.value(f"{robot}_online") for robot in [*ids, f"v{args.vehicles:03d}"]), 120)
        if ready is None:
            raise SystemExit("not every vehicle reported within 120 s")
        probe = next(task for task in runtime.tasks if task.name == "fast")
        probe.stats.latency.reset()
        nodes = list(master.roadmap.nodes.values())
        ends = time.monotonic() + args.seconds
        while time.monotonic() < ends:
            for robot in ids:
                if master.links[robot].trip is None and not db.value(f"{robot}_status") and rng.random() < 0.2:
                    goal = rng.choice(nodes)
                    db.submit([(f"{robot}_xgoal", goal.x), (f"{robot}_ygoal", goal.y), (f"{robot}_status", True)], "bench")
            await asyncio.sleep(0.5)
        latency = probe.stats.latency.summary()
        result.update(task_p99=latency["p99"], task_max=latency["max"])
        figures = master.metrics()
        result.update(orders=recorder.orders, acknowledged=len(recorder.latencies), violations=len(recorder.violations) + figures["schema_violations"],
                      conflicts=figures["reservation_conflicts"], deadlocks=figures["deadlocks_broken"],
                      p50=float(np.percentile(recorder.latencies, 50) * 1e3) if recorder.latencies else float("nan"),
                      p95=float(np.percentile(recorder.latencies, 95) * 1e3) if recorder.latencies else float("nan"),
                      p99=float(np.percentile(recorder.latencies, 99) * 1e3) if recorder.latencies else float("nan"))
        # A frozen vehicle: its MQTT session lives on (no will for 1.5 x 5 s), its states stop.
        last = f"v{args.vehicles:03d}"
        os.kill(frozen.pid, signal.SIGSTOP)
        result["flagged_s"] = await until(lambda: not db.value(f"{last}_online"), 30) or float("nan")
        # The goal's measure: from its last state (the clock's time it came) to the master flagging it.
        result["silence_s"] = runtime.clock.now() - master.links[last].last_state_at
        os.kill(frozen.pid, signal.SIGCONT)
        # The broker restarts: from its return to the master subscribed again and hearing the vehicles.
        broker.stop()
        await until(lambda: not db.value("_sys.vda5050.broker"), 30)
        await asyncio.sleep(2.0)
        heard = {robot: master.links[robot].states for robot in ids}
        broker.start()
        result["resubscribed_s"] = await until(lambda: db.value("_sys.vda5050.broker") and
                                               sum(master.links[robot].states > heard[robot] for robot in ids) >= len(ids) // 2, 60) or float("nan")
        processes.append(frozen)
    finally:
        for process in processes:
            if process.returncode is None:
                process.kill()
        recording.cancel()
        await recorder.connection.close()
        await runtime.stop()
        broker.remove()
        shutil.rmtree(directory, ignore_errors=True)
    return result


def main() -> None:
    import logging

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--log", default="vda5050-fleet.log", metavar="FILE", help="the runtime's log lines (default vda5050-fleet.log)")
    args = parser.parse_args()
    logging.basicConfig(filename=args.log, level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    print(f"load average before: {load_average()}; the runtime's log in {args.log}")
    result = asyncio.run(run(args))
    print(f"{args.vehicles} vda-5050-lib vehicles on mosquitto, {args.seconds:g} s of random goals (load average after: {load_average()})")
    print(f"  orders {result['orders']}, acknowledged by a state {result['acknowledged']}; order -> acknowledging state "
          f"p50 {result['p50']:.1f} ms, p95 {result['p95']:.1f} ms, p99 {result['p99']:.1f} ms")
    print(f"  10 ms task start latency p99 {result['task_p99']:.3f} ms, max {result['task_max']:.3f} ms")
    print(f"  schema violations {result['violations']}, reservation conflicts {result['conflicts']}, deadlocks broken {result['deadlocks']}")
    print(f"  a frozen vehicle (state every {STATE_INTERVAL:g} s) flagged {result['silence_s']:.2f} s after its last state "
          f"({result['flagged_s']:.2f} s after it froze); "
          f"after a broker restart subscribed again and hearing vehicles in {result['resubscribed_s']:.2f} s")
    goals = [
        ("order -> acknowledging state p95 <= 100 ms" + (" (the goal is set for 100 vehicles)" if args.vehicles > 100 else ""),
         result["p95"] <= 100),
        ("10 ms task p99 start latency <= 1 ms", result["task_p99"] <= 1.0),
        ("0 schema violations", result["violations"] == 0),
        ("re-subscribed <= 5 s after the broker returns", result["resubscribed_s"] <= 5.0),
        (f"a lost vehicle flagged <= {2 * STATE_INTERVAL:g} s (2x its state interval) after its last state",
         result["silence_s"] <= 2 * STATE_INTERVAL),
    ]
    for text, met in goals:
        print(f"{text}: {'met' if met else 'GOAL MISSED'}")


if __name__ == "__main__":
    main()
