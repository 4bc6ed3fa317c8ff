"""Two members of a pair in one process on the real clock, with a real etcd: election, sync, takeover, refusals.

(The fault tests — kill -9, SIGSTOP, a cut link — run the members as processes: test_pair_faults.py.)
"""

from __future__ import annotations

import argparse
import asyncio
import time
from pathlib import Path
from typing import Any

import pytest

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.plant_role import PlantRole
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule
from tests.adapters.redundancy.pair_support import write_pair

OPERATOR = Origin("opcua", "olga", "127.0.0.1", role=Role.OPERATOR)


def member(path: Path, name: str, state: Path) -> Runtime:
    config = load_config(path)
    runtime = Runtime(config, state_dir=state / name)
    for adapter in build_adapters(config, argparse.Namespace(redundancy_member=name)):
        runtime.add_adapter(adapter)
    return runtime


async def until(condition: Any, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout} s: {what}")
        await asyncio.sleep(0.01)


def role(runtime: Runtime) -> str:
    return runtime.db.value("_sys.redundancy.role")


@pytest.fixture
async def pair(tmp_path: Path, etcd: Any) -> Any:
    path = write_pair(tmp_path, etcd.endpoint)
    a, b = member(path, "a", tmp_path), member(path, "b", tmp_path)
    # One after the other: in one process the members share one event loop, and b's start (its
    # journals created on a disk the suite keeps busy) would hold up a's first lease renewal — two
    # processes do not share that (test_pair_faults.py starts two at once).
    await a.start()
    await until(lambda: role(a) == "ACTIVE", 10, "a active")
    await b.start()
    yield a, b
    for runtime in (a, b):
        await runtime.stop()


async def test_the_preferred_member_becomes_active_and_the_other_mirrors_it(pair: Any) -> None:
    a, b = pair
    await until(lambda: role(a) == "ACTIVE" and b.db.value("_sys.redundancy.peer_ok"), 10, "a active and b in sync")
    assert role(b) == "STANDBY" and b.db.value("_sys.redundancy.active") == "a"
    assert a.db.value("_sys.redundancy.service_level") == 255 and b.db.value("_sys.redundancy.service_level") == 100
    assert a.db.value("_sys.redundancy.epoch") == b.db.value("_sys.redundancy.epoch") > 0
    await until(lambda: a.db.value("_sys.redundancy.peer_ok"), 5, "a sees its standby in sync")
    await until(lambda: b.db.value("scans") >= 50, 5, "b mirrors the scans")
    assert b.tasks[0].stats.cycles == 0
    (refused,) = b.db.submit([("spare", 1)], OPERATOR)
    assert refused is not None and refused.rule is Rule.NOT_ACTIVE and "write to the active, a" in refused.detail
    assert a.db.submit([("spare", 7)], OPERATOR) == [None]
    await until(lambda: b.db.value("spare") == 7, 2, "the write reaches the standby")


async def test_when_the_active_stops_the_standby_takes_over_at_once_and_carries_on(pair: Any) -> None:
    a, b = pair
    await until(lambda: b.db.value("_sys.redundancy.peer_ok") and b.db.value("scans") > 20, 10, "b in sync")
    assert a.db.submit([("setpoint", 4.5)], OPERATOR) == [None]
    started = time.monotonic()
    await a.stop()  # a clean stop gives the lease up: no wait for its end
    await until(lambda: role(b) == "ACTIVE", 3, "b active")
    assert time.monotonic() - started < 1.5
    scans = b.db.value("scans")
    await until(lambda: b.db.value("scans") > scans + 10, 2, "b scans")
    assert b.db.value("setpoint") == 4.5 and b.db.value("edges") == 1  # no false edge of `part`
    assert b.db.value("_sys.redundancy.failovers") == 1 and b.db.value("_sys.redundancy.epoch") > a.db.value("_sys.redundancy.epoch")


async def test_a_member_whose_loop_stalls_before_it_asks_for_the_lease_is_not_fenced_by_the_stall(
        tmp_path: Path, etcd: Any, caplog: pytest.LogCaptureFixture) -> None:
    # The event loop held up for longer than the lease (3 s) between the look at who holds the key
    # and the request for a lease (another adapter's start writing to a disk under load did this in
    # a suite run): the lease counts from its request, so the term does too — a member that counted
    # it from before the stall took over with a term already over, fenced at once.
    path = write_pair(tmp_path, etcd.endpoint)
    a = member(path, "a", tmp_path)
    coordinator = next(adapter for adapter in a.adapters if adapter.name == "redundancy").coordinator
    look = coordinator.look
    stalled = []

    async def stalling_look() -> Any:
        held = await look()
        if not stalled and a.state.value == "RUNNING":  # the look before the campaign's request for a lease
            stalled.append(True)
            time.sleep(3.5)  # noqa: ASYNC251 — the whole loop, as a blocking call in another adapter would
        return held

    coordinator.look = stalling_look
    left_at_takeover: list[float] = []  # of each ACTIVE term, when it was given: how long it had to run
    a.role.on_change(lambda term: left_at_takeover.append(term.until - a.clock.now()) if term.role is PlantRole.ACTIVE else None)
    await a.start()
    try:
        await until(lambda: role(a) == "ACTIVE", 10, "a active")
        await until(lambda: a.tasks[0].stats.cycles > 20, 5, "a scans")
        assert stalled
        assert left_at_takeover and left_at_takeover[0] > 0, left_at_takeover  # not over before it began
        assert not [record for record in caplog.records if "lapsed" in record.getMessage()]
    finally:
        await a.stop()

