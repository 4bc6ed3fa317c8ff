"""A pair is one plant to the outside: only its active sends — Sparkplug B births and data, writes to
other controllers over links — and a standby that takes over goes on where the active left off.

Two members in one process on the real clock with a real etcd and mosquitto; the Sparkplug host is
pysparkplug (its own venv), the linked controller pymodbus's own Modbus server.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from tests.adapters.redundancy.pair_support import write_pair
from tests.adapters.redundancy.test_pair_inprocess import member, role, until
from tests.links_support import PymodbusRemote, links_of
from tests.sparkplug_support import SparkplugHost, check_seq, metric

OPERATOR = Origin("opcua", "olga", "127.0.0.1", role=Role.OPERATOR)

SPARKPLUG = """
mqtt: {{url: "mqtt://127.0.0.1:{port}"}}
sparkplug:
  group_id: pairs
  edge_node_id: pairtest
  devices:
    - {{id: line, tags: "s*"}}
"""

LINK = """
links:
  press: {{protocol: modbus, host: 127.0.0.1, port: {port}, period: 50ms, timeout: 1s, backoff_max: 1s}}
"""
LINKED_TAG = '  press_setpoint: {type: uint16, link: {name: press, source: "holding:7", direction: out}}\n'


def carries(event: dict[str, Any], name: str, value: Any) -> bool:
    """A DDATA with metric `name` at `value`."""
    return event["type"] == "DDATA" and any(m["name"] == name and m["value"] == value for m in event["metrics"])


async def start_pair(path: Path, folder: Path) -> tuple[Any, Any]:
    a, b = member(path, "a", folder), member(path, "b", folder)
    await asyncio.gather(a.start(), b.start())
    await until(lambda: role(a) == "ACTIVE" and b.db.value("_sys.redundancy.peer_ok"), 10, "a active and b in sync")
    return a, b


async def test_only_the_active_is_the_sparkplug_edge_node_and_the_new_active_births_with_the_next_bdseq(
        tmp_path: Path, etcd: Any, mosquitto: Any) -> None:
    host = await SparkplugHost.start(mosquitto.port, "pairs")
    path = write_pair(tmp_path, etcd.endpoint, extra=SPARKPLUG.format(port=mosquitto.port))
    a, b = await start_pair(path, tmp_path)
    try:
        first = await host.wait(lambda e: e["type"] == "NBIRTH", what="the active's NBIRTH")
        await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", what="the active's DBIRTH")
        assert a.db.submit([("setpoint", 2.5)], OPERATOR) == [None]
        await host.wait(lambda e: carries(e, "setpoint", 2.5), what="the active's data")
        await until(lambda: b.db.value("setpoint") == 2.5, 2, "the standby mirrors the write")
        # The standby is the same edge node: it has no session, so no will and no births of its own.
        assert b.db.value("_sys.sparkplug.connected") is False and b.db.value("_sys.sparkplug.state").startswith("standby")
        assert len(host.of("NBIRTH")) == 1
        mark = host.mark()
        await a.stop()  # a clean stop: its NDEATH, and the lease given up at once
        await until(lambda: role(b) == "ACTIVE", 3, "b active")
        death = await host.wait(lambda e: e["type"] == "NDEATH", since=mark, what="the old active's NDEATH")
        assert death["bdSeq"] == first["bdSeq"]
        birth = await host.wait(lambda e: e["type"] == "NBIRTH", since=mark, what="the new active's NBIRTH")
        # Numbered after the old session: a late will of the old active (frozen, not stopped) cannot end it.
        assert birth["bdSeq"] == (first["bdSeq"] + 1) % 256
        dbirth = await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", since=mark, what="the new DBIRTH")
        assert metric(dbirth, "setpoint")["value"] == 2.5  # the mirrored state, born as it was
        assert b.db.submit([("setpoint", 3.5)], OPERATOR) == [None]
        await host.wait(lambda e: carries(e, "setpoint", 3.5), since=mark, what="the new active's data")
        check_seq(host.events, "pairtest")
    finally:
        for runtime in (a, b):
            await runtime.stop()
        host.close()


async def test_only_the_active_writes_to_a_linked_controller(tmp_path: Path, etcd: Any) -> None:
    remote = PymodbusRemote()
    await remote.start()
    path = write_pair(tmp_path, etcd.endpoint, extra=LINK.format(port=remote.port))
    path.write_text(path.read_text().replace("tags:\n", "tags:\n" + LINKED_TAG, 1))
    a, b = await start_pair(path, tmp_path)
    try:
        link_a, link_b = links_of(a).links["press"], links_of(b).links["press"]
        await until(lambda: link_a.connected and link_b.connected, 5, "both members' links up (reading)")
        for value in (5, 6):
            assert a.db.submit([("press_setpoint", value)], OPERATOR) == [None]
            await until(lambda v=value: remote.holding[7] == v and b.db.value("press_setpoint") == v, 3,
                        f"{value} written by the active and mirrored on the standby")
        # The standby's image changed too (mirrored), and its link wrote none of it: the active did
        # (its count goes up when the remote's answer is read, just after the remote holds the value).
        await until(lambda: link_a.writes["ok"] >= 2, 3, "the active's writes answered")
        assert link_b.writes == {"ok": 0, "refused": 0, "failed": 0}
        await a.stop()
        await until(lambda: role(b) == "ACTIVE", 3, "b active")
        assert b.db.submit([("press_setpoint", 7)], OPERATOR) == [None]
        await until(lambda: remote.holding[7] == 7 and link_b.writes["ok"] >= 1, 3, "the new active writes out, answered")
    finally:
        for runtime in (a, b):
            await runtime.stop()
        await remote.stop()
