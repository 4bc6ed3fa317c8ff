"""A pair of `softplc run` processes on loopback with a real etcd (1 s lease), hit by the faults of issue 25.

Started at once (the preferred member is active), the sync link cut by a proxy, kill -9 of the
active, SIGSTOP of the active (then SIGCONT: it must fence and come back as standby), etcd stopped
and started. After each: exactly one active, the standby in sync, the program's state continuous
(its scan counter never goes back or skips more than a cycle, its edge counter never counts a
false edge), every write acknowledged Good is there, and the device that receives every output
with its epoch never sees an older epoch after a newer one (two actives never overlap). asyncua's
HaClient and a node-opcua client follow the active. One pair for the file's tests, in order.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import signal
import time
from typing import Any

import pytest
import pytest_asyncio
from tools_support import missing

from tests.adapters.redundancy.pair_process import PASSWORD, Pair
from tests.conftest import REPO
from tests.etcd_server import EtcdServer, EtcdUnavailable

pytestmark = pytest.mark.asyncio(loop_scope="module")
NODE_DIR = REPO / "tests" / "node"


class Observer:
    """Reads the members' tags over OPC UA (one session each, re-opened after a restart)."""

    def __init__(self, pair: Pair) -> None:
        self.pair = pair
        self.clients: dict[str, Any] = {}

    async def _client(self, name: str) -> Any:
        from asyncua import Client

        if name not in self.clients:
            client = Client(self.pair.members[name].endpoint, timeout=1)
            client.set_user("olga")
            client.set_password(PASSWORD)
            await asyncio.wait_for(client.connect(), 3)
            self.clients[name] = (client, await client.get_namespace_index("urn:softplc:tags"))
        return self.clients[name]

    async def _drop(self, name: str) -> None:
        entry = self.clients.pop(name, None)
        if entry is not None:
            entry[0].disconnect_socket()

    async def read(self, name: str, *tags: str) -> list[Any] | None:
        from asyncua import ua

        if not self.pair.members[name].alive():
            return None
        try:
            client, ns = await self._client(name)
            return await asyncio.wait_for(client.read_values([client.get_node(ua.NodeId(tag, ns)) for tag in tags]), 2)
        except Exception:
            await self._drop(name)
            return None

    async def write(self, name: str, tag: str, value: int) -> str:
        """The status of writing `value` (uint32) to `tag` on `name`: Good, a Bad... name, or 'unreachable'."""
        from asyncua import ua

        try:
            client, ns = await self._client(name)
            node = client.get_node(ua.NodeId(tag, ns))
            await asyncio.wait_for(node.write_value(ua.DataValue(ua.Variant(value, ua.VariantType.UInt32))), 1)
            return "Good"
        except ua.UaStatusCodeError as error:
            return ua.StatusCode(error.code).name
        except Exception:
            await self._drop(name)
            return "unreachable"

    async def roles(self) -> dict[str, str | None]:
        found = {}
        for name in self.pair.members:
            values = await self.read(name, "_sys.redundancy.role")
            found[name] = values[0] if values else None
        return found

    async def settle(self, timeout: float = 20.0) -> str:
        """Wait until one member is ACTIVE and the other STANDBY in sync; returns the active's name."""
        deadline = time.monotonic() + timeout
        last: Any = None
        while time.monotonic() < deadline:
            states = {}
            for name in self.pair.members:
                states[name] = await self.read(name, "_sys.redundancy.role", "_sys.redundancy.peer_ok")
            last = states
            if all(states.values()):
                actives = [name for name, (role, _) in states.items() if role == "ACTIVE"]
                standbys = [name for name, (role, ok) in states.items() if role == "STANDBY" and ok]
                if len(actives) == 1 and len(standbys) == 1:
                    return actives[0]
            await asyncio.sleep(0.1)
        raise AssertionError(f"the pair did not settle within {timeout} s: {last}\n{self.pair.logs()}")

    async def close(self) -> None:
        for name in list(self.clients):
            await self._drop(name)


class Writer:
    """Writes 1, 2, 3... to `spare` on whichever member accepts it; remembers the last value acknowledged Good."""

    def __init__(self, observer: Observer) -> None:
        self.observer = observer
        self.acknowledged = 0
        self.statuses: dict[str, int] = {}
        self.goods: list[tuple[float, str, int]] = []  # (monotonic time, member, value) of every Good
        self._task: asyncio.Task[None] | None = None

    def start(self, first: int) -> None:
        self.next = first
        self._stopping = False
        self._task = asyncio.ensure_future(self._run())

    async def _run(self) -> None:
        names = list(self.observer.pair.members)
        while not self._stopping:
            for name in names:
                status = await self.observer.write(name, "spare", self.next)
                self.statuses[status] = self.statuses.get(status, 0) + 1
                if status == "Good":
                    self.goods.append((time.monotonic(), name, self.next))
                    self.acknowledged = self.next
                    self.next += 1
                    break
            await asyncio.sleep(0.01)

    async def stop(self) -> None:
        # A flag besides the cancel: asyncua's request to a member being killed can swallow the
        # CancelledError, and the loop then wrote on for ever (seen: the suite hung here).
        assert self._task is not None
        self._stopping = True
        self._task.cancel()
        await asyncio.wait({self._task}, timeout=5)


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def pair(tmp_path_factory: Any) -> Any:

    try:
        etcd = EtcdServer()
    except EtcdUnavailable as error:
        missing(str(error))
    etcd.start()
    try:
        pair = Pair(tmp_path_factory.mktemp("pair"), etcd)
        await pair.start()  # both at once
        observer = Observer(pair)
        try:
            yield pair, observer
        finally:
            await observer.close()
            await pair.stop()
    finally:
        etcd.remove()


async def softplc(*arguments: str) -> tuple[int, str]:
    """Run a `softplc` client command (its own process: the test's loop keeps serving the proxy)."""
    import os
    import sys

    environment = {**os.environ, "SOFTPLC_PASSWORD": PASSWORD}
    process = await asyncio.create_subprocess_exec(sys.executable, "-m", "softplc", *arguments, env=environment,
                                                   stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT)
    output, _ = await asyncio.wait_for(process.communicate(), 60)
    return process.returncode or 0, output.decode()


def both(pair: Pair, first: str) -> str:
    """Both endpoints, `first` first: the CLI must find the active whatever the order."""
    other = next(name for name in pair.members if name != first)
    return f"{pair.members[first].endpoint},{pair.members[other].endpoint}"


def no_overlap(pair: Pair) -> None:
    assert pair.device.overlaps() == [], "two actives drove outputs at once"


async def continuity(pair: Pair, observer: Observer, active: str) -> None:
    """The active's program state carried on: one rising edge ever, the scan counter as the outputs saw it."""
    values = await observer.read(active, "edges", "scans")
    assert values is not None and values[0] == 1, f"edges {values}: a false edge"
    outputs = [output.scans for output in list(pair.device.outputs)]
    steps = [b - a for a, b in zip(outputs, outputs[1:])]
    assert min(steps) >= 0, "the scan counter went back"


async def test_both_started_at_once_the_preferred_member_is_active(pair: Any) -> None:
    pair, observer = pair
    assert await observer.settle(60) == "a"  # two processes starting on a busy machine: OPC UA alone takes seconds
    assert (await observer.read("b", "_sys.redundancy.active", "_sys.redundancy.service_level")) == ["a", 100]
    assert (await observer.read("a", "_sys.redundancy.service_level"))[0] == 255
    assert (await observer.write("b", "spare", 5)) == "BadInvalidState"  # the standby refuses, naming no one in OPC UA
    # the CLI given both endpoints, the standby's first, writes to the active; given the standby
    # alone it says who the active is
    code, output = await softplc("write", "spare=77", "--endpoint", both(pair, "b"), "--user", "olga")
    assert code == 0, output
    assert (await observer.read("a", "spare")) == [77]
    code, output = await softplc("write", "spare=78", "--endpoint", pair.members["b"].endpoint, "--user", "olga")
    assert code == 1 and "not active: this runtime (b) is the standby of its redundant pair: write to the active, a" in output, output
    no_overlap(pair)


async def test_a_cut_sync_link_degrades_the_pair_without_a_second_active(pair: Any) -> None:
    pair, observer = pair
    assert await observer.settle() == "a"
    assert pair.proxy is not None
    pair.proxy.sever()
    deadline = time.monotonic() + 5
    while (await observer.read("b", "_sys.redundancy.degraded")) != [True]:
        assert time.monotonic() < deadline, "the standby never said the pair is degraded"
        await asyncio.sleep(0.1)
    await asyncio.sleep(1.5)  # longer than the lease: etcd still says a is active
    assert await observer.roles() == {"a": "ACTIVE", "b": "STANDBY"}
    assert (await observer.read("a", "_sys.redundancy.peer_ok", "_sys.redundancy.service_level")) == [False, 200]
    pair.proxy.restore()
    assert await observer.settle(10) == "a"
    no_overlap(pair)


async def follow_with_node(pair: Pair, seconds: float) -> asyncio.subprocess.Process:
    node = shutil.which("node")
    if node is None or not (NODE_DIR / "node_modules" / "node-opcua-client").is_dir():
        pytest.fail("node and tests/node/node_modules are needed: run scripts/install-test-tools.sh")
    endpoints = [member.endpoint for member in pair.members.values()]
    return await asyncio.create_subprocess_exec(node, "redundancy_follow.js", str(seconds), *endpoints, cwd=NODE_DIR,
                                                stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)


async def test_kill_9_of_the_active_the_standby_serves_writes_in_about_a_second_and_clients_follow(pair: Any) -> None:
    from asyncua.client.ha.ha_client import HaClient, HaConfig, HaMode

    pair, observer = pair
    active = await observer.settle()
    standby = next(name for name in pair.members if name != active)
    ha = HaClient(HaConfig(HaMode.WARM, keepalive_timer=1, manager_timer=1, reconciliator_timer=1, session_timeout=10,
                           request_timeout=2, urls=[member.endpoint for member in pair.members.values()]))
    await ha.start()
    node = await follow_with_node(pair, 25)
    seen: list[str] = []
    try:
        deadline = time.monotonic() + 15
        while ha.active_client is None or ha.active_client.server_url.geturl() != pair.members[active].endpoint:
            assert time.monotonic() < deadline, "HaClient never chose the active"
            await asyncio.sleep(0.1)
        assert node.stdout is not None
        while not any(f'"using":"{pair.members[active].endpoint}"' in line for line in seen):
            seen.append((await asyncio.wait_for(node.stdout.readline(), max(0.1, deadline - time.monotonic()))).decode())
        writer = Writer(observer)
        writer.start(first=1000)
        await asyncio.sleep(1.0)
        assert writer.acknowledged > 1000
        pair.members[active].kill()
        killed = time.monotonic()
        while not any(member == standby and at > killed for at, member, _ in writer.goods):
            assert time.monotonic() - killed < 5, f"the standby never served a write: {writer.statuses}"
            await asyncio.sleep(0.02)
        takeover = next(at for at, member, _ in writer.goods if member == standby and at > killed) - killed
        await asyncio.sleep(0.5)
        await writer.stop()
        assert takeover < 3.0, f"the standby served writes {takeover:.2f} s after the kill"  # the goal, 1.5 s p95: bench/
        # The last acknowledged write is journaled, applied at the next cycle boundary: read until
        # it shows (a read right after the answer can come before that cycle on a busy machine).
        applied_by = time.monotonic() + 2.0
        spare = (await observer.read(standby, "spare"))[0]
        while spare < writer.acknowledged and time.monotonic() < applied_by:
            await asyncio.sleep(0.05)
            spare = (await observer.read(standby, "spare"))[0]
        assert spare >= writer.acknowledged, f"a write acknowledged Good ({writer.acknowledged}) was lost: {spare}"
        # The dead active's last output, read once it is dead: a datagram it sent just before the
        # kill may reach the device's thread after that (read before the kill: 813, then 815 from
        # the standby, which had the state of 814 — a fresh-clone run under load).
        before = pair.device.last(active)
        first = next(output for output in pair.device.outputs if output.member == standby)
        assert before is not None and before.scans <= first.scans <= before.scans + 1, (before, first)  # ≤ 1 cycle of state lost
        assert first.epoch > before.epoch
        await continuity(pair, observer, standby)
        code, output = await softplc("read", "spare", "--endpoint", both(pair, active))  # the old active is dead: the new one answers
        assert code == 0, output
        shown = int(next(line for line in output.splitlines() if line.startswith("spare")).split()[1])
        assert shown >= spare, output  # (a write cancelled in flight by the writer's stop may land after `spare` was read)
        deadline = time.monotonic() + 10
        while ha.active_client is None or ha.active_client.server_url.geturl() != pair.members[standby].endpoint:
            assert time.monotonic() < deadline, "HaClient did not fail over to the new active"
            await asyncio.sleep(0.1)
        stdout, stderr = await asyncio.wait_for(node.communicate(), 40)
        output = "".join(seen) + stdout.decode()
        lines = [json.loads(line[len("ACTIVE "):]) for line in output.splitlines() if line.startswith("ACTIVE ")]
        result = [json.loads(line[len("RESULT "):]) for line in output.splitlines() if line.startswith("RESULT ")]
        assert result, stderr.decode()[-2000:]
        usings = [line["using"] for line in lines if line["using"]]
        assert usings and usings[-1] == pair.members[standby].endpoint, output  # it used the active, and follows the new one
        assert pair.members[active].endpoint in usings, output
        redundancy = result[0]["redundancy"][pair.members[standby].endpoint]
        assert redundancy["support"] == 3 and sorted(redundancy["uris"]) == ["urn:softplc:pairtest:a", "urn:softplc:pairtest:b"]
    finally:
        pair.members[active].start()  # the old active returns: as the standby, and resyncs
        if node.returncode is None:
            node.kill()
        # HaClient.stop() may wait for ever on a client of the dead server (its reconnect loop):
        # give it a few seconds, never the whole test.
        await asyncio.wait({asyncio.ensure_future(ha.stop())}, timeout=5)
    assert await observer.settle(25) == standby
    no_overlap(pair)


async def test_a_frozen_active_is_replaced_and_fences_itself_when_it_wakes_up(pair: Any) -> None:
    pair, observer = pair
    active = await observer.settle()
    standby = next(name for name in pair.members if name != active)
    frozen = pair.members[active]
    frozen.signal(signal.SIGSTOP)
    stopped = time.monotonic()
    try:
        while (await observer.read(standby, "_sys.redundancy.role")) != ["ACTIVE"]:
            assert time.monotonic() - stopped < 5, "the standby did not take over from a frozen active"
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.5)
    finally:
        frozen.signal(signal.SIGCONT)
    woke = time.monotonic()
    assert await observer.settle(15) == standby
    late = [output for output in pair.device.outputs if output.member == active and output.received > woke]
    assert late == [], f"the frozen active drove {len(late)} output(s) after it woke up"
    no_overlap(pair)
    await continuity(pair, observer, standby)


async def test_etcd_stopped_fences_the_active_and_after_its_restart_exactly_one_is_active(pair: Any) -> None:
    pair, observer = pair
    active = await observer.settle()
    values = await observer.read(active, "_sys.redundancy.epoch")
    pair.etcd.stop()
    stopped = time.monotonic()
    try:
        while (await observer.read(active, "_sys.redundancy.role")) != ["FENCED"]:
            assert time.monotonic() - stopped < 4, "the active did not fence itself without its coordinator"
            await asyncio.sleep(0.05)
        fenced = time.monotonic()
        await asyncio.sleep(1.0)
        assert [output for output in pair.device.outputs if output.received > fenced + 0.05] == []  # no outputs while fenced
        assert (await observer.read(active, "_sys.redundancy.service_level")) == [1]
        roles = await observer.roles()
        assert list(roles.values()).count("ACTIVE") == 0
    finally:
        pair.etcd.start()
    now_active = await observer.settle(15)
    epoch = (await observer.read(now_active, "_sys.redundancy.epoch"))[0]
    assert values is not None and epoch >= values[0]
    no_overlap(pair)
    await continuity(pair, observer, now_active)
