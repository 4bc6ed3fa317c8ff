"""Stalls on the real clock: a setup() that blocks is blamed on its own program wherever it runs
(a restart inside a cycle, an operator's reset outside any cycle, start-up), and what a console
and the protocol clients see of a stall, and when (docs/runtime.md, "Stalls")."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime, RuntimeState
from softplc.core.clock import RealClock

CORE = REPO / "tests" / "core_programs.py"
STUCK_IN_SETUP = "task fast is stuck in setup() of program slow for "


@pytest.fixture
def real_runtime(make_config, tmp_path: Path) -> Callable[[str], Runtime]:
    def build(text: str) -> Runtime:
        return Runtime(make_config(text), RealClock(), state_dir=tmp_path / "state")

    return build


async def wait_until(condition: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll `condition` every 10 ms (yielding to the runtime) until it holds or `timeout` passes."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(0.01)


class ErrorWatch:
    """A thread that records the runtime's first ERROR as it saw it, even while the loop is blocked."""

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        self.first: tuple[str, bool] | None = None  # (error, a cycle or setup was under way)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        while not self._stop.wait(0.01):
            if self.runtime.state is RuntimeState.ERROR and self.first is None:
                self.first = (self.runtime.error, self.runtime.engine.current is not None)

    def __enter__(self) -> ErrorWatch:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def plant(programs: list[str], **slow: object) -> str:
    params = ", ".join(f"{key}: {value}" for key, value in {"block": 1.0, **slow}.items())
    entries = {
        "count": f'{{name: count, program: "{CORE}:Counter", bind: {{count: n}}}}',
        "slow": f'{{name: slow, program: "{CORE}:SlowSetup", bind: {{scans: slow_scans}}, params: {{{params}}}, '
                "restart: {delay: 100ms, max: 1}}",
    }
    listed = "\n".join(f"      - {entries[name]}" for name in programs)
    return f"""
version: 1
tags:
  n: {{type: uint32}}
  slow_scans: {{type: uint32}}
runtime:
  stall_after: 300ms
tasks:
  fast:
    interval: 10ms
    programs:
{listed}
"""


@pytest.mark.parametrize("order", [["count", "slow"], ["slow", "count"]])
async def test_a_setup_blocking_in_an_automatic_restart_is_blamed_on_its_own_program(real_runtime, order: list[str]) -> None:
    """`slow` fails its first scan, is restarted 100 ms later inside a cycle, and that setup() blocks."""
    runtime = real_runtime(plant(order))
    db = runtime.db
    slow, count = runtime.program("slow"), runtime.program("count")
    with ErrorWatch(runtime) as watch:
        await runtime.start()
        try:
            await wait_until(lambda: db.value("_sys.state") == "ERROR", 10, "the stall to be published")
            assert watch.first is not None and watch.first[1] is True  # reported while still stuck
            assert watch.first[0].startswith(STUCK_IN_SETUP), watch.first
            # the culprit is FAULTED with the stall; the healthy program was never touched
            assert slow.state.value == "FAULTED" and slow.faults == 2 and slow.error == runtime.error
            assert slow.error.startswith(STUCK_IN_SETUP)
            assert count.state.value == "RUNNING" and count.faults == 0 and count.error == ""
            assert db.value("_sys.fast.count.state") == "RUNNING" and db.value("_sys.fast.slow.state") == "FAULTED"
            scans = db.value("n")
            await wait_until(lambda: db.value("n") >= scans + 10, 5, "the healthy program to keep scanning")
        finally:
            await runtime.stop()


async def test_a_setup_blocking_in_an_operator_reset_is_watched_and_faults_its_program(real_runtime) -> None:
    """The reset runs setup() from the housekeeping, outside any cycle: still watched, still named."""
    runtime = real_runtime(plant(["count", "slow"]).replace("restart: {delay: 100ms, max: 1}", "restart: never"))
    db = runtime.db
    slow = runtime.program("slow")
    await runtime.start()
    try:
        await wait_until(lambda: slow.state.value == "FAULTED", 5, "the first scan's fault")
        assert runtime.state is RuntimeState.RUNNING
        with ErrorWatch(runtime) as watch:
            db.submit([("_sys.reset_faults", True)], "operator")
            # the reset is done (and its setup returned) once the command tag reads false again
            await wait_until(lambda: slow.program.setups == 2 and db.value("_sys.reset_faults") is False, 10, "the reset")
        assert watch.first is not None and watch.first[1] is True, watch.first  # seen while the setup blocked
        assert watch.first[0].startswith(STUCK_IN_SETUP), watch.first
        assert runtime.state is RuntimeState.ERROR and runtime.error == watch.first[0]  # the reset did not clear it
        assert slow.state.value == "FAULTED" and slow.faults == 2 and slow.error == runtime.error
        assert db.value("_sys.state") == "ERROR" and db.value("_sys.fast.slow.error") == runtime.error
        assert runtime.program("count").state.value == "RUNNING"
    finally:
        await runtime.stop()


async def test_a_setup_blocking_at_start_up_is_watched_and_faults_its_program(real_runtime) -> None:
    runtime = real_runtime(plant(["count", "slow"], block_on=1))
    slow = runtime.program("slow")
    with ErrorWatch(runtime) as watch:
        await runtime.start()
        try:
            assert watch.first is not None and watch.first[1] is True, watch.first
            assert watch.first[0].startswith(STUCK_IN_SETUP), watch.first
            # start() does not paper over it with RUNNING
            assert runtime.state is RuntimeState.ERROR and runtime.db.value("_sys.state") == "ERROR"
            assert slow.state.value == "FAULTED" and slow.error == runtime.error
        finally:
            await runtime.stop()


# -- what is visible when (item 16): console at once, protocol clients once the loop runs ------

# A short stall (0.4 s, reported 0.2 s in) armed just after a publication of the system tags, so
# that the next one (every 0.5 s) is not yet due when it ends: what clients see right after the
# stall is what the end of the stuck cycle published, not the housekeeping's next round.
STALL = f"""
version: 1
tags:
  armed: {{type: bool}}
  done: {{type: uint32}}
runtime:
  stall_after: 200ms
tasks:
  fast:
    interval: 10ms
    programs:
      - {{name: block, program: "{CORE}:Blocker", bind: {{armed: armed, done: done}}, params: {{block: 0.4, once: true}}}}
"""


class StallLog(logging.Handler):
    """Records each stall report: its text, its thread, and whether the loop was still stuck then."""

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(logging.ERROR)
        self.runtime = runtime
        self.records: list[tuple[float, str, str, bool]] = []

    def emit(self, record: logging.LogRecord) -> None:
        if "is stuck in" in record.getMessage():
            stuck = self.runtime.engine.current is not None
            self.records.append((time.monotonic(), record.threadName or "", record.getMessage(), stuck))


@pytest.fixture
def stall_log() -> Iterator[Callable[[Runtime], StallLog]]:
    handlers: list[StallLog] = []
    logger = logging.getLogger("softplc.engine.stall")

    def attach(runtime: Runtime) -> StallLog:
        handler = StallLog(runtime)
        logger.addHandler(handler)
        handlers.append(handler)
        return handler

    yield attach
    for handler in handlers:
        logger.removeHandler(handler)


class Poller:
    """Reads `_sys.state` again and again from its own thread; records (answered at, value)."""

    def __init__(self, read: Callable[[], str]) -> None:
        self.read = read
        self.answers: list[tuple[float, str]] = []
        self.errors: list[BaseException] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()

    def _poll(self) -> None:
        while not self._stop.is_set():
            try:
                value = self.read()
            except BaseException as error:  # reported by the test, never swallowed
                self.errors.append(error)
                return
            self.answers.append((time.monotonic(), value))
            self._stop.wait(0.01)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)

    def after(self, moment: float) -> list[tuple[float, str]]:
        return [answer for answer in self.answers if answer[0] > moment]


async def test_a_stall_is_on_the_console_at_once_and_over_the_protocols_once_the_loop_runs(
    make_config, tmp_path: Path, stall_log
) -> None:
    from asyncua.sync import Client as SyncOpcUaClient
    from pymodbus.client import ModbusTcpClient

    from softplc.adapters.modbus.server import ModbusAdapter
    from softplc.adapters.modbus.settings import ModbusSettings
    from softplc.adapters.opcua import OpcUaServer, OpcUaSettings

    config = make_config(STALL)
    modbus = ModbusAdapter(config, ModbusSettings(**{**ModbusSettings.from_servers(config.servers).__dict__, "enabled": True, "port": 0}))
    opcua = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/"))
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    runtime.add_adapter(modbus)
    runtime.add_adapter(opcua)
    db, fast = runtime.db, runtime.tasks[0]
    log = stall_log(runtime)
    # (event, cycles of the task so far): the stuck cycle's output, and _sys.state turning ERROR
    events: list[tuple[str, int]] = []
    arm_after_next_publication = False

    def changed(tags: object) -> None:
        nonlocal arm_after_next_publication
        for tag in tags:  # type: ignore[attr-defined]
            if tag.name == "done":
                events.append(("stuck cycle committed", fast.stats.cycles))
            elif tag.name == "_sys.state" and tag.value == "ERROR":
                events.append(("_sys.state ERROR", fast.stats.cycles))
            elif tag.name == "_sys.time" and arm_after_next_publication:
                arm_after_next_publication = False
                db.submit([("armed", True)], "test")

    db.on_change(changed)
    await runtime.start()
    mapping = modbus.map.by_tag["_sys.state"]
    codec = mapping.codec
    assert codec is not None
    pollers: list[Poller] = []
    clients: list[object] = []
    try:
        # Clients in threads of their own, so they keep asking while the runtime's loop is blocked.
        def connect() -> None:
            modbus_client = ModbusTcpClient("127.0.0.1", port=modbus.port, timeout=5, retries=0)
            assert modbus_client.connect()
            opcua_client = SyncOpcUaClient(opcua.endpoint, timeout=5)
            opcua_client.connect()
            clients.extend([modbus_client, opcua_client])

        await asyncio.to_thread(connect)
        modbus_client, opcua_client = clients
        state_node = opcua_client.get_node(f"ns={opcua.namespace_index};s=_sys.state")  # type: ignore[attr-defined]

        def read_modbus() -> str:
            response = modbus_client.read_input_registers(mapping.address, count=mapping.words)  # type: ignore[attr-defined]
            assert not response.isError(), response
            return str(codec.decode(response.registers))

        pollers = [Poller(read_modbus), Poller(state_node.read_value)]
        await wait_until(lambda: all(p.answers and p.answers[-1][1] == "RUNNING" for p in pollers), 10, "both clients to read RUNNING")

        arm_after_next_publication = True
        await wait_until(lambda: runtime.program("block").state.value == "FAULTED", 10, "the stall to end")
        ended = time.monotonic()
        await wait_until(lambda: all(len(p.after(ended)) >= 3 for p in pollers), 10, "answers after the stall")
        await wait_until(lambda: db.value("_sys.state") == "ERROR", 5, "_sys.state to read ERROR")
        for poller in pollers:
            assert not poller.errors, poller.errors

        # The console: the watcher thread reported while the loop was still stuck.
        assert log.records, "no stall report"
        reported_at, thread, message, stuck = log.records[0]
        assert thread == "softplc-stall-detector" and stuck is True
        assert message.startswith("task fast is stuck in program block for ")
        # The tags: _sys.state turned ERROR at the end of the stuck cycle itself, before any other
        # cycle ran (not at the next publication of the system tags, up to 0.5 s later).
        stuck_cycle, error_at = dict(events)["stuck cycle committed"], dict(events)["_sys.state ERROR"]
        assert error_at - stuck_cycle <= 1, events  # the stuck cycle is counted between the two
        # The protocols share the blocked loop: no answer between the report and the end of the
        # stall (0.4 s blocked, reported 0.2-0.25 s in)...
        for poller in pollers:
            assert poller.after(reported_at)[0][0] - reported_at > 0.1, poller.answers[-5:]
        # ...and Modbus's first answer after it already says ERROR (its registers are read from the
        # tag database when a request is served).
        assert pollers[0].after(reported_at)[0][1] == "ERROR", pollers[0].after(reported_at)
        # OPC UA pushes the change into its address space in the moments after: ERROR, then no RUNNING.
        opcua_after = [value for _, value in pollers[1].after(reported_at)]
        assert "ERROR" in opcua_after and "RUNNING" not in opcua_after[opcua_after.index("ERROR"):], opcua_after
    finally:
        for poller in pollers:
            poller.stop()

        def disconnect() -> None:
            for client in clients:
                (client.disconnect if hasattr(client, "disconnect") else client.close)()  # type: ignore[attr-defined]

        await asyncio.to_thread(disconnect)
        await runtime.stop()
