"""Helpers of the HMI tests: a small plant with robots and tasks, users, a running HMI, a browser.

The browser is Debian's Chromium driven by Playwright (never `playwright install`); the flags
are those of FIELD-NOTES. A failed browser test saves a screenshot under tests/artifacts/hmi/.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import textwrap
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import aiohttp
import pytest_asyncio

from softplc.adapters.hmi.server import HmiServer
from softplc.adapters.hmi.settings import HmiSettings
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.program import InOut, Input, Output, Program
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from softplc.security.users import UserStore

REPO = Path(__file__).resolve().parent.parent
ARTIFACTS = REPO / "tests" / "artifacts" / "hmi"
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
BROWSER_TIMEOUT = 8000  # ms: a 2-core machine shared by several test runs
PASSWORDS = {"viewer": "viewer-pass-1", "operator": "operator-pass-1", "engineer": "engineer-pass-1"}
TEST_HASH_COST = 10  # log2 N: milliseconds per login instead of the default's ~0.4 s
SCRIPT_DESCRIPTION = '<script>window.__pwned = 1</script><img src=x onerror="window.__pwned = 2"> a <b>bold</b> claim'
DRIVER = Origin("test-driver", role=None)  # writes like a robot driver: no access rule

ROBOTS_YAML = """
robots:
  - {id: r01, name: Rover One, driver: sim, length_mm: 255, width_mm: 255, height_mm: 400, load_capacity: 20,
     max_linear_speed: 0.2, max_angular_speed: 0.4, hardware: [laser_range_finder, camera, two_wheel_drive, sonar, gripper],
     start: {x: 7.925, y: 5.925}}
  - {id: r02, name: Rover Two, driver: sim, length_mm: 255, width_mm: 255, height_mm: 400, load_capacity: 20,
     max_linear_speed: 0.2, max_angular_speed: 0.4, hardware: [laser_range_finder, two_wheel_drive, gripper],
     start: {x: 7.925, y: 2.925}}
"""
TASKS_YAML = """
tasks:
  - {id: t01, name: Task One, max_length_mm: 400, max_width_mm: 500, max_height_mm: 600, min_load_capacity: 10,
     min_linear_speed: 0.1, min_angular_speed: 0.2, max_team_size: 2, requires: [laser_range_finder, gripper],
     source: {x: 3.5, y: 7.5}, destination: {x: 1.8, y: 2.5}}
  - {id: t02, name: Task Two, max_length_mm: 500, max_width_mm: 600, max_height_mm: 700, min_load_capacity: 10,
     min_linear_speed: 0.1, min_angular_speed: 0.2, max_team_size: 2, requires: [laser_range_finder, camera, sonar],
     source: {x: 18.5, y: 7.5}, destination: {x: 20.1, y: 2.4}}
"""
VIEW_SVG = """<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="400" height="200" viewBox="0 0 400 200">
  <script>window.__pwned = 3</script>
  <rect id="tank" x="10" y="10" width="40" height="100" style="fill:#eeeeee;stroke:#333333" onclick="window.__pwned = 4"/>
  <rect id="level" x="12" y="12" width="36" height="96" style="fill:#2e6fd1"/>
  <text id="items" x="70" y="40" style="font-size:20px"><tspan id="items_span">0</tspan></text>
  <text id="sum" x="70" y="80">0</text>
  <g id="alarm"><rect x="70" y="100" width="120" height="30" style="fill:#fde7e5"/><text x="80" y="120">HIGH</text></g>
  <g id="robot"><circle cx="0" cy="0" r="6" style="fill:#7e22ce"/></g>
  <rect id="button" x="250" y="20" width="100" height="40" style="fill:#1a7f37"/>
  <rect id="state" x="250" y="80" width="100" height="20" style="fill:#888888"/>
</svg>
"""


def plant_yaml(*, anonymous: str | None = None, description: str = SCRIPT_DESCRIPTION, blobs: int = 0) -> str:
    """The test plant: two robots (fleet not driven: tests move them), two tasks, a view, a 10 ms task.

    `blobs`: that many string tags b001_text... more (for tests that need a lot of traffic).
    """
    hmi = f"\n    anonymous: {anonymous}" if anonymous else ""
    pad = " " * 10  # the template's indentation in the text below, before dedent
    blob = f"\n{pad}blob:\n{pad}  group: Blobs\n{pad}  count: {blobs}\n{pad}  prefix: b\n{pad}  tags:\n{pad}    text: {{type: string, modbus: {{enabled: false}}}}" if blobs else ""
    return textwrap.dedent(f"""
        version: 1
        plant: {{name: "hmi <b>test</b> plant", description: "a plant for the HMI tests"}}
        templates:
          robot:
            group: Robots
            instances: [r01, r02]
            tags:
              xpos:     {{type: float64, unit: m, access: ro, description: x position}}
              ypos:     {{type: float64, unit: m, access: ro, description: y position}}
              heading:  {{type: float64, unit: rad, access: ro}}
              navstate: {{type: string, initial: idle, access: ro}}
              status:   {{type: bool}}
              tcurr:    {{type: uint16, max: 99}}
              currloc:  {{type: uint16, max: 4}}
            initial:
              r01: {{xpos: 7.925, ypos: 5.925}}
              r02: {{xpos: 7.925, ypos: 2.925}}
          task:
            group: Tasks
            instances: [t01, t02]
            tags:
              iBM: {{type: uint16, unit: items, min: 0, max: 10000, description: input buffer items}}
              iBL: {{type: float32, unit: "%", min: 0, max: 100, access: ro, description: input buffer level}}
              iBC: {{type: uint16, initial: 100, unit: items, min: 1, max: 10000}}
              iFr: {{type: float32, initial: 30, unit: items/min, min: 0, max: 6000, description: input fill rate}}
              qSM: {{type: uint16, unit: items, min: 0, max: 10000}}
              qSL: {{type: float32, unit: "%", min: 0, max: 100, access: ro}}{blob}
        tags:
          note:    {{type: string, initial: hello, description: '{description.replace("'", "''")}'}}
          counter: {{type: uint32, access: ro, description: scans of the fast task}}
          limit:   {{type: float64, min: 0, max: 100, unit: bar, description: a bounded rw tag}}
          flag:    {{type: bool}}
        tasks:
          fast:
            interval: 10ms
            programs:
              - name: count
                program: tests.hmi_support:Counter
                bind: {{count: counter}}
              - name: faulty
                program: tests.hmi_support:Faulty
                bind: {{trip: flag}}
              - name: level_{{task}}
                program: tests.hmi_support:Level
                for_each: task
                bind: {{items: "{{task}}_iBM", capacity: "{{task}}_iBC", level: "{{task}}_iBL"}}
        fleet:
          enabled: false
          robots: robots.yaml
          tasks: tasks.yaml
          map: {REPO / "robots" / "maps" / "factory.yaml"}
        servers:
          hmi:
            host: 127.0.0.1
            port: 0{hmi}
        hmi:
          views:
            test:
              title: Test view
              svg: view.svg
              bindings:
                level: {{bar: {{tag: t01_iBL}}, fill: {{tag: t01_iBL, thresholds: [[0, "#2e6fd1"], [80, "#b3261e"]]}}}}
                items: {{text: {{tag: t01_iBM, unit: pcs}}}}
                sum:   {{text: {{expr: "t01_iBM + t02_iBM", decimals: 0}}}}
                alarm: {{visible: "t01_iBL >= 80"}}
                robot: {{translate: {{x: r01_xpos, y: r01_ypos, scale: [10, -10], offset: [200, 190]}}}}
                button: {{click: {{tag: limit, write: 42}}}}
                state: {{fill: {{expr: "_sys.state == 'RUNNING'", on_color: "#1a7f37", off_color: "#b3261e"}}}}
        """)


class Counter(Program):
    """Counts scans: a tag that changes every 10 ms."""

    count = InOut("scans so far")

    def scan(self) -> None:
        self.count = (self.count + 1) % 2**32


class Level(Program):
    """level = 100 * items / capacity: a buffer's level follows a write of its items."""

    items = Input("items")
    capacity = Input("capacity")
    level = Output("level, %")

    def scan(self) -> None:
        self.level = min(100.0, 100.0 * self.items / max(self.capacity, 1))


class Faulty(Program):
    """Raises while `trip` is true: a program fault to see and reset."""

    trip = Input("fault while true")

    def scan(self) -> None:
        if self.trip:
            raise RuntimeError("tripped by the test")


def write_plant(folder: Path, text: str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robots.yaml").write_text(ROBOTS_YAML)
    (folder / "tasks.yaml").write_text(TASKS_YAML)
    (folder / "view.svg").write_text(VIEW_SVG)
    path = folder / "tagdb.yaml"
    path.write_text(text if text is not None else plant_yaml())
    return path


def add_users(state_dir: Path) -> None:
    store = UserStore(state_dir / "users.yaml")
    for role in Role:
        store.add(role.value, role, PASSWORDS[role.value], log2_n=TEST_HASH_COST)


@dataclass
class Plant:
    """A running runtime with its HMI (and whatever other adapters were asked for)."""

    runtime: Runtime
    hmi: HmiServer
    adapters: dict[str, Any]

    @property
    def url(self) -> str:
        return self.hmi.url

    @property
    def db(self) -> Any:
        return self.runtime.db

    def drive(self, **values: Any) -> None:
        """Write tags the way a driver or program would (no access rule), e.g. drive(r01_xpos=3.0)."""
        results = self.db.submit(list(values.items()), DRIVER)
        assert all(result is None for result in results), results

    async def stop(self) -> None:
        await self.runtime.stop()


async def start_plant(folder: Path, *, text: str | None = None, modbus: bool = False, opcua: bool = False,
                      users: bool = True, clock: Any = None, start: bool = True, **settings: Any) -> Plant:
    """Write the plant into `folder`, start it (unless `start=False`) with the HMI on a free port (or settings['port'])."""
    path = write_plant(folder, text)
    state = folder / "state"
    if users:
        add_users(state)
    config = load_config(path)
    runtime = Runtime(config, clock or RealClock(), state_dir=state)
    adapters: dict[str, Any] = {}
    if opcua:
        from softplc.adapters.opcua import OpcUaServer, OpcUaSettings

        adapters["opcua"] = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/"))
    if modbus:
        from softplc.adapters.modbus.server import ModbusAdapter
        from softplc.adapters.modbus.settings import ModbusSettings

        adapters["modbus"] = ModbusAdapter(config, ModbusSettings(enabled=True, port=0))
    hmi = HmiServer(config, HmiSettings.from_config(config).override(**settings))
    for adapter in [*adapters.values(), hmi]:
        runtime.add_adapter(adapter)
    if start:
        await runtime.start()
    return Plant(runtime, hmi, adapters)


async def wait_until(condition: Callable[[], Any], timeout: float = 5.0, message: str = "condition") -> Any:
    """Poll `condition` (sync) every 10 ms until it is truthy; fail after `timeout` s."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f"{message} not met within {timeout} s")
        await asyncio.sleep(0.01)


def chromium_available() -> bool:
    return Path(CHROMIUM).exists() and shutil.which("chromium") is not None


def require_browser() -> None:
    """At a browser test module's top: skip it without playwright or Chromium — under CI, fail it (tools_support.missing)."""
    from tools_support import missing

    if not playwright_available():
        missing("the playwright package is not installed (pip install -e .[test]; scripts/bootstrap.sh test)", module=True)
    if not chromium_available():
        missing("Debian's chromium is not installed (scripts/install-test-tools.sh)", module=True)


def playwright_available() -> bool:
    try:
        import playwright.async_api  # noqa: F401
    except ImportError:
        return False
    return True


def http_client() -> aiohttp.ClientSession:
    """An HTTP client that keeps its cookies (the session) as a browser would."""
    # unsafe=True: aiohttp's cookie jar ignores cookies of IP-address hosts (127.0.0.1) otherwise.
    return aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True))


async def http_login(session: aiohttp.ClientSession, url: str, user: str) -> str:
    """Log `session` in as `user` through POST /api/login; returns the CSRF token."""
    async with session.post(url + "api/login", json={"user": user, "password": PASSWORDS[user]}) as response:
        assert response.status == 200, await response.text()
        return (await response.json())["csrf"]


async def post_command(session: aiohttp.ClientSession, url: str, name: str, arguments: Any = None, csrf: str | None = None,
                       **headers: str) -> tuple[int, Any]:
    """POST /api/commands/NAME with `arguments` as JSON; returns (status, the whole answer read as strict JSON)."""
    sent = {"X-CSRF-Token": csrf} if csrf else {}
    data = json.dumps(arguments if arguments is not None else {})
    async with session.post(url + f"api/commands/{name}", data=data, headers={"Content-Type": "application/json", **sent, **headers}) as response:
        return response.status, strict_json(await response.text())


async def receive_until(ws: aiohttp.ClientWebSocketResponse, wanted: str | Callable[[dict[str, Any]], bool],
                        timeout: float = 5.0) -> dict[str, Any]:
    """The next live-channel message of type `wanted` (or for which `wanted(message)` is true), read as strict JSON."""
    deadline = time.monotonic() + timeout
    while True:
        message = strict_json((await ws.receive(timeout=max(0.01, deadline - time.monotonic()))).data)
        if (message["type"] == wanted) if isinstance(wanted, str) else wanted(message):
            return message


def strict_json(text: str) -> Any:
    """JSON as a browser's JSON.parse reads it: NaN and Infinity are errors (Python's json accepts them)."""
    def refuse(constant: str) -> Any:
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def browser() -> AsyncIterator[Any]:
    """Debian's Chromium for a test module (import this fixture into the module that uses it)."""
    from playwright.async_api import async_playwright

    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield browser
        await browser.close()


async def open_page(browser: Any, url: str, *, width: int = 1280, height: int = 800) -> tuple[Any, Any, list[str]]:
    """A fresh context (no cookies) and page at `url`; returns (context, page, console errors)."""
    context = await browser.new_context(viewport={"width": width, "height": height})
    page = await context.new_page()
    page.set_default_timeout(BROWSER_TIMEOUT)
    errors: list[str] = []
    page.on("console", lambda message: errors.append(message.text) if message.type == "error" else None)
    page.on("pageerror", lambda error: errors.append(str(error)))
    await page.goto(url)
    return context, page, errors


async def ready(page: Any) -> None:
    """Wait until the HMI has drawn its page."""
    await page.wait_for_selector("main[data-ready='1']")


async def log_in(page: Any, user: str) -> None:
    """Log in as `user` (viewer, operator or engineer) through the login dialog; the page is drawn again."""
    await page.click("#user-box button")
    await page.fill("#login-user", user)
    await page.fill("#login-password", PASSWORDS[user])
    await page.click("dialog form button[type=submit]")
    await page.wait_for_selector(f"#user-box .who[data-role='{user}']")
    await ready(page)


@asynccontextmanager
async def screenshot_on_failure(page: Any, name: str) -> AsyncIterator[None]:
    """Save a screenshot of `page` as tests/artifacts/hmi/NAME.png if the block fails."""
    try:
        yield
    except BaseException:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        try:
            await page.screenshot(path=str(ARTIFACTS / f"{name}.png"), full_page=True)
        except Exception:
            pass
        raise
