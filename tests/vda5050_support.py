"""Helpers for the VDA 5050 tests: a plant with VDA 5050 vehicles on the factory roadmap, a wire recorder, waiting."""

from __future__ import annotations

import asyncio
import json
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.protocols.mqtt import MqttConnection
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.protocols.vda5050.validation import problems

MAP = REPO / "robots" / "maps" / "factory.yaml"
ROADMAP = REPO / "robots" / "roadmap.yaml"

TEMPLATE = """\
version: 1
plant: {{name: vda}}
templates:
  robot:
    instances_from:
      file: robots.yaml
      initial: {{xpos: start.x, ypos: start.y, heading: start.heading, xgoal: start.x, ygoal: start.y}}
    tags:
      xpos:      {{type: float64, access: ro}}
      ypos:      {{type: float64, access: ro}}
      heading:   {{type: float64, access: ro}}
      speed:     {{type: float64, access: ro}}
      navstate:  {{type: string, initial: idle, access: ro}}
      navreason: {{type: string, access: ro}}
      radius:    {{type: float64, access: ro}}
      route:     {{type: string, access: ro}}
      status:    {{type: bool}}
      xgoal:     {{type: float64}}
      ygoal:     {{type: float64}}
      online:    {{type: bool, access: ro}}
      currloc:   {{type: uint16}}
      tcurr:     {{type: uint16}}
mqtt: {{url: "{url}", keepalive: 2s}}
vda5050:
  roadmap: {roadmap}
  version: "{version}"
  ack_timeout: {ack_timeout}
  lost_after: {lost_after}
  tick: 50ms
"""


def vehicle_yaml(robot_id: str, serial: str, x: float, y: float, *, speed: float = 0.8, manufacturer: str = "softplc",
                 key: str = "actions") -> str:
    return textwrap.dedent(f"""\
      - id: {robot_id}
        driver: vda5050
        vda5050: {{manufacturer: {manufacturer}, serial_number: {serial}, instant_actions_key: {key}}}
        length_mm: 255
        width_mm: 255
        height_mm: 400
        load_capacity: 20
        max_linear_speed: {speed}
        max_angular_speed: 2.0
        hardware: [laser_range_finder, two_wheel_drive, gripper]
        start: {{x: {x}, y: {y}, heading: 0}}
    """)


def write_plant(directory: Path, url: str, robots: list[str], *, version: str = "2.0", ack_timeout: str = "500ms",
                lost_after: str = "2s", extra: str = "", fleet: bool = False) -> Path:
    """tagdb.yaml + robots.yaml; `fleet`: drive the sim robots too (else the fleet section only names the files)."""
    (directory / "robots.yaml").write_text("robots:\n" + "".join(textwrap.indent(robot, "  ") for robot in robots))
    path = directory / "tagdb.yaml"
    path.write_text(TEMPLATE.format(url=url, roadmap=ROADMAP, version=version, ack_timeout=ack_timeout, lost_after=lost_after)
                    + f"fleet: {{enabled: {str(fleet).lower()}, robots: robots.yaml, map: {MAP}}}\n" + extra)
    return path


async def start_plant(tagdb: Path, *, hmi: bool = False, opcua: bool = False) -> Runtime:
    """The plant's runtime with every adapter its configuration builds (fleet, vda5050, alarms...), on the real clock;
    with `hmi`, the web HMI too, on a free port (`adapter(runtime, "hmi").url`)."""
    from softplc.app.adapters import build_adapters

    config = load_config(tagdb)
    runtime = Runtime(config, RealClock(), state_dir=tagdb.parent / "state")
    for adapter in build_adapters(config, None):
        if adapter.name in ("opcua", "modbus", "hmi", "history", "metrics"):
            continue
        runtime.add_adapter(adapter)
    if hmi:
        from softplc.adapters.hmi.server import HmiServer
        from softplc.adapters.hmi.settings import HmiSettings

        runtime.add_adapter(HmiServer(config, HmiSettings.from_config(config).override(port=0)))
    if opcua:  # on a free port (`adapter(runtime, "opcua").endpoint`), with a user of each role (tests/opcua_support.py)
        from softplc.adapters.opcua import OpcUaServer, OpcUaSettings
        from tests.opcua_support import add_users

        (tagdb.parent / "state").mkdir(exist_ok=True)
        add_users(tagdb.parent / "state")
        runtime.add_adapter(OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/")))
    await runtime.start()
    return runtime


def adapter(runtime: Runtime, name: str) -> Any:
    return next(item for item in runtime.adapters if item.name == name)


async def wait_for(condition: Callable[[], bool], timeout: float, what: str) -> float:
    """Poll every 10 ms until `condition()` holds; fail with `what` after `timeout` seconds (real time)."""
    start = time.monotonic()
    while not condition():
        if time.monotonic() - start > timeout:
            raise AssertionError(f"timed out after {timeout} s waiting for: {what}")
        await asyncio.sleep(0.01)
    return time.monotonic() - start


class Wire:
    """Every order and instant action on the broker, recorded by an independent MQTT client and checked against the schemas."""

    def __init__(self, port: int, version: str) -> None:
        self.version = version
        self.messages: list[tuple[float, str, dict[str, Any]]] = []
        self.violations: list[str] = []
        self.connection = MqttConnection(MqttSettings(port=port, client_id="wire"), "recorder", RealClock())
        self.connection.subscribe("uagv/+/+/+/order", self._record)
        self.connection.subscribe("uagv/+/+/+/instantActions", self._record)
        self.task: asyncio.Task[Any] | None = None

    def _record(self, topic: str, payload: bytes, retained: bool) -> None:
        message = json.loads(payload)
        kind = topic.rsplit("/", 1)[-1]
        if kind == "instantActions" and "actions" not in message and "instantActions" in message:
            message = {**message, "actions": message["instantActions"]}  # the vda-5050-lib quirk, sent on purpose
            del message["instantActions"]
        found = problems("order" if kind == "order" else "instantActions", self.version, message)
        self.violations += [f"{topic}: {problem}" for problem in found]
        self.messages.append((time.monotonic(), topic, message))

    def orders(self, serial: str) -> list[dict[str, Any]]:
        return [message for _, topic, message in self.messages if topic.endswith(f"/{serial}/order")]

    async def __aenter__(self) -> Wire:
        self.task = asyncio.ensure_future(self.connection.run())
        await wait_for(lambda: self.connection.connected, 10, "the recorder connected")
        return self

    async def __aexit__(self, *exc: Any) -> None:
        assert self.task is not None
        self.task.cancel()
        await self.connection.close()


NODE_DIR = REPO / "tests" / "vda5050_node"


class LibVehicles:
    """vda-5050-lib virtual vehicles (tests/vda5050_node/vehicles.js) in one Node process: `kill()` is a crash."""

    def __init__(self, port: int, vehicles: list[dict[str, Any]], **options: Any) -> None:
        self.config = {"broker": f"mqtt://127.0.0.1:{port}", "vehicles": vehicles, "heartbeat": 2, "stateInterval": 1000, **options}
        self.process: Any = None

    @staticmethod
    def require() -> None:
        """Skip the test when vda-5050-lib is missing, except under CI (CI=true): there, fail it with what is missing."""
        from tools_support import missing

        lacking = LibVehicles.available()
        if lacking:
            missing(lacking)

    @staticmethod
    def available() -> str:
        """'' when Node.js and vda-5050-lib are installed, else what is missing."""
        import shutil

        if shutil.which("node") is None:
            return "node is missing (apt-get install nodejs npm, or scripts/install-test-tools.sh)"
        if not (NODE_DIR / "node_modules" / "vda-5050-lib").is_dir():
            return "vda-5050-lib is missing (scripts/install-test-tools.sh installs it into tests/vda5050_node)"
        return ""

    async def __aenter__(self) -> LibVehicles:
        self.process = await asyncio.create_subprocess_exec(
            "node", str(NODE_DIR / "vehicles.js"), json.dumps(self.config), cwd=NODE_DIR,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT)
        assert self.process.stdout is not None
        line = await asyncio.wait_for(self.process.stdout.readline(), 30)
        if b'"ready"' not in line:
            rest = await asyncio.wait_for(self.process.stdout.read(4000), 5)
            raise RuntimeError(f"vehicles.js did not start: {(line + rest).decode(errors='replace')}")
        return self

    def kill(self) -> None:
        self.process.kill()

    async def __aexit__(self, *exc: Any) -> None:
        if self.process.returncode is None:
            self.process.terminate()
            try:
                await asyncio.wait_for(self.process.wait(), 10)
            except asyncio.TimeoutError:
                self.process.kill()
                await self.process.wait()
