"""Sparkplug B sessions as an independent host (pysparkplug) sees them: seq and bdSeq across a broker
restart and a kill -9 of `softplc run`, and store and forward while the primary host is offline."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from softplc.core.tagdb import Origin
from tests.adapters.sparkplug.test_sparkplug_host import PLANT, start_plant
from tests.sparkplug_support import SparkplugHost, check_seq, metric

PROGRAM = Origin("program", role=None)


async def until(condition, timeout: float = 10.0, what: str = "condition") -> None:  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"{what}: not within {timeout} s"
        await asyncio.sleep(0.02)


async def test_seq_and_bdseq_across_a_broker_restart(mosquitto, tmp_path: Path) -> None:
    host = await SparkplugHost.start(mosquitto.port, "plant1")
    runtime = await start_plant(tmp_path, mosquitto.port)
    try:
        await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", what="the first births")
        for value in range(1, 4):
            runtime.db.submit([("total", float(value))], PROGRAM)
            await host.wait(lambda e, v=value: e["type"] == "DDATA" and metric(e, "total")["value"] == v, what=f"total = {value}")
        mosquitto.stop()
        await until(lambda: not runtime.db.value("_sys.sparkplug.connected"), what="the node notices")
        runtime.db.submit([("total", 99.0)], PROGRAM)  # while the broker is away: stored
        await until(lambda: runtime.db.value("_sys.sparkplug.stored") == 1, what="the change stored")
        mark = host.mark()
        mosquitto.start()
        await host.wait(lambda e: e["type"] == "ready", since=mark, timeout=15, what="the host back")
        # Whoever reconnected first, the host ends up with the new session's births (asking for them when it missed them).
        await until(lambda: runtime.db.value("_sys.sparkplug.state") == "online", timeout=15, what="the node born again")
        if not host.of("NBIRTH", since=mark):
            await host.send({"op": "rebirth", "node": "line1"})
        nbirth = await host.wait(lambda e: e["type"] == "NBIRTH", since=mark, what="the NBIRTH of the new session")
        assert (nbirth["seq"], nbirth["bdSeq"]) == (0, 1)  # a new MQTT session: bdSeq + 1
        runtime.db.submit([("total", 100.0)], PROGRAM)
        await host.wait(lambda e: e["type"] == "DDATA" and metric(e, "total")["value"] == 100.0, since=mark, what="live data again")
        await until(lambda: runtime.db.value("_sys.sparkplug.stored") == 0, what="the store emptied")
    finally:
        await runtime.stop()
    await host.wait(lambda e: e["type"] == "NDEATH", what="the NDEATH")
    assert host.of("NDEATH")[-1]["bdSeq"] == 1
    check_seq(host.events, "line1")
    host.close()


async def test_a_kill_9_of_the_runtime_brings_its_will_and_the_next_run_the_next_bdseq(mosquitto, tmp_path: Path) -> None:
    (tmp_path / "tagdb.yaml").write_text(PLANT.format(port=mosquitto.port, extra=""))
    host = await SparkplugHost.start(mosquitto.port, "plant1")
    command = [sys.executable, "-m", "softplc", "run", str(tmp_path / "tagdb.yaml"), "--no-history"]
    runs = []
    try:
        for run in range(2):
            mark = host.mark()
            process = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            runs.append(process)
            nbirth = await host.wait(lambda e: e["type"] == "NBIRTH", since=mark, timeout=30, what=f"run {run + 1}'s NBIRTH")
            assert (nbirth["seq"], nbirth["bdSeq"]) == (0, run)  # bdSeq goes on from the last run's (kept in .softplc/)
            await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", since=mark, what="the DBIRTHs")
            os.kill(process.pid, signal.SIGKILL)
            process.wait(timeout=10)
            death = await host.wait(lambda e: e["type"] == "NDEATH", since=mark, what="the will after kill -9")
            assert death["bdSeq"] == nbirth["bdSeq"]  # the host can tell which birth it ends
            assert not host.of("DDEATH", since=mark)  # killed: no goodbye, only the broker's will
    finally:
        for process in runs:
            if process.poll() is None:
                process.kill()
                process.wait(timeout=10)
        host.close()
    check_seq(host.events, "line1")


async def test_while_the_primary_host_is_offline_data_is_stored_and_forwarded_historical_in_order(mosquitto, tmp_path: Path) -> None:
    host = await SparkplugHost.start(mosquitto.port, "plant1", host_id="scada")
    runtime = await start_plant(tmp_path, mosquitto.port, extra="primary_host: scada\n")
    try:
        writes: list = []
        runtime.db.on_write(writes.extend)
        await until(lambda: runtime.db.value("_sys.sparkplug.state") == "waiting for primary host", what="waiting for the host")
        assert not host.of("NBIRTH")  # no birth before the primary host is online (§5.6)
        await host.send({"op": "dcmd", "node": "line1", "device": "line", "metrics": [{"name": "total", "datatype": "DOUBLE", "value": 1.0}]})
        await until(lambda: len(writes) == 1, what="the command to an unborn node refused")
        assert writes[0].rule is not None and "not online" in writes[0].detail and runtime.db.value("total") == 0.0
        await host.send({"op": "state", "online": True})
        nbirth = await host.wait(lambda e: e["type"] == "NBIRTH", what="the births once the host is online")
        assert nbirth["bdSeq"] == 0
        await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", what="the DBIRTHs")

        mark = host.mark()
        await host.send({"op": "state", "online": False})
        death = await host.wait(lambda e: e["type"] == "NDEATH", since=mark, what="the NDEATH as the host goes offline")
        assert death["bdSeq"] == 0
        await until(lambda: runtime.db.value("_sys.sparkplug.state") == "waiting for primary host" and runtime.db.value("_sys.sparkplug.connected"),
                    what="a new session, waiting")
        assert runtime.db.value("_sys.sparkplug.primary_host_online") is False
        offline_values = [10.0, 11.0, 12.0, 13.0, 14.0]
        for value in offline_values:
            runtime.db.submit([("total", value)], PROGRAM)
            await until(lambda v=value: runtime.db.value("total") == v, what="the change applied")
        # Gathered for a second, then on disk: every change, in fewer messages.
        await until(lambda: 1 <= runtime.db.value("_sys.sparkplug.stored") <= len(offline_values), what="the changes stored")
        assert not host.of("DDATA", since=mark)

        mark = host.mark()
        await host.send({"op": "state", "online": True})
        nbirth = await host.wait(lambda e: e["type"] == "NBIRTH", since=mark, what="the births when the host is back")
        assert nbirth["bdSeq"] == 1
        dbirth = await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", since=mark, what="line's DBIRTH")
        assert metric(dbirth, "total")["value"] == 14.0  # the birth carries the current value
        await host.wait(lambda e: len([m for d in host.of("DDATA", since=mark) for m in d["metrics"] if m["historical"]]) == len(offline_values),
                        since=mark, what="every stored value forwarded")
        historical = [m for d in host.of("DDATA", since=mark) for m in d["metrics"] if m["historical"]]
        assert [m["value"] for m in historical] == offline_values  # in order
        stamps = [m["timestamp"] for m in historical]
        assert stamps == sorted(stamps) and stamps[-1] <= nbirth["timestamp"]  # their own times, before the birth
        runtime.db.submit([("total", 15.0)], PROGRAM)
        live = await host.wait(lambda e: e["type"] == "DDATA" and any(m["value"] == 15.0 for m in e["metrics"]), since=mark, what="live data")
        assert not live["metrics"][0]["historical"]
        await until(lambda: runtime.db.value("_sys.sparkplug.stored") == 0, what="the store emptied")
        check_seq(host.events, "line1")
    finally:
        await runtime.stop()
        host.close()
