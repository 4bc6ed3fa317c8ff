"""The Sparkplug B edge node as an independent host sees it: pysparkplug 0.6.1 (its own venv) over mosquitto.

Births with names, aliases, datatypes, values and properties; data by exception decoded by alias;
quality changes; deaths on stop; Rebirth; DCMD writes through the tag database's rules and roles.
"""

from __future__ import annotations

import logging
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.tagdb import Origin, Rule, WriteEvent
from softplc.core.tags import Quality
from softplc.protocols.sparkplug import sparkplug_b_pb2 as pb
from tests.sparkplug_support import SparkplugHost, check_seq, metric

PLANT = """\
version: 1
plant: {{name: line1}}
templates:
  task:
    instances: [t01, t02]
    tags:
      iBM: {{type: uint16, unit: items, min: 0, max: 10000, description: input buffer items}}
      iBL: {{type: float32, unit: "%", min: 0, max: 100, access: ro, description: input buffer level}}
      iFr: {{type: float32, initial: 30, min: 0, max: 6000}}
tags:
  heading: {{type: int16, initial: -5}}
  label: {{type: string, initial: hello}}
  running: {{type: bool}}
  total: {{type: float64}}
  panel_setpoint: {{type: float64}}
tasks:
  fast: {{interval: 10ms}}
servers: {{opcua: {{enabled: false}}, modbus: {{enabled: false}}, hmi: {{enabled: false}}}}
mqtt: {{url: "mqtt://127.0.0.1:{port}"}}
sparkplug:
  group_id: plant1
  devices:
    - template: task
    - {{id: panel, tags: "panel_*", role: viewer}}
    - {{id: line, tags: "*"}}
{extra}"""

PROGRAM = Origin("program", role=None)


async def start_plant(tmp_path: Path, port: int, extra: str = "", before: Any = None) -> Runtime:
    path = tmp_path / "tagdb.yaml"
    path.write_text(PLANT.format(port=port, extra=textwrap.indent(textwrap.dedent(extra), "  ")))
    config = load_config(path)
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    for adapter in build_adapters(config, None):
        runtime.add_adapter(adapter)
    if before is not None:
        before(runtime)
    await runtime.start()
    return runtime


def birth_of(host: SparkplugHost, device: str, since: int = 0) -> dict[str, Any]:
    return host.of("DBIRTH", device, since)[-1]


async def test_births_data_quality_and_deaths_as_an_independent_host_decodes_them(mosquitto, tmp_path: Path) -> None:
    host = await SparkplugHost.start(mosquitto.port, "plant1")
    runtime = await start_plant(tmp_path, mosquitto.port)
    try:
        nbirth = await host.wait(lambda e: e["type"] == "NBIRTH", what="the NBIRTH")
        assert (nbirth["node"], nbirth["seq"], nbirth["bdSeq"]) == ("line1", 0, 0)
        rebirth = metric(nbirth, "Node Control/Rebirth")
        assert (rebirth["datatype"], rebirth["value"], rebirth["alias"]) == ("BOOLEAN", False, None)
        await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", what="the last DBIRTH")
        assert [e["device"] for e in host.of("DBIRTH")] == ["t01", "t02", "panel", "line"]

        t01 = birth_of(host, "t01")
        assert [(m["name"], m["datatype"]) for m in t01["metrics"]] == [("iBM", "UINT16"), ("iBL", "FLOAT"), ("iFr", "FLOAT")]
        assert metric(t01, "iFr")["value"] == 30.0
        assert metric(t01, "iBM")["properties"] == {"engUnit": "items", "engLow": 0.0, "engHigh": 10000.0,
                                                   "documentation": "input buffer items", "readOnly": False}
        assert metric(t01, "iBL")["properties"]["readOnly"] is True  # ro: an operator's DCMD may not write it
        assert metric(birth_of(host, "panel"), "panel_setpoint")["properties"]["readOnly"] is True  # a viewer device
        line = birth_of(host, "line")
        assert {m["name"]: (m["datatype"], m["value"]) for m in line["metrics"]} == {
            "heading": ("INT16", -5), "label": ("STRING", "hello"), "running": ("BOOLEAN", False), "total": ("DOUBLE", 0.0)}
        aliases = [m["alias"] for e in host.of("DBIRTH") for m in e["metrics"]]
        assert None not in aliases and len(set(aliases)) == len(aliases)  # unique across the node

        mark = host.mark()
        runtime.db.submit([("t01_iBM", 7), ("heading", -300), ("label", "wörld")], PROGRAM)
        t01_data = await host.wait(lambda e: e["type"] == "DDATA" and e["device"] == "t01", what="t01's DDATA", since=mark)
        line_data = await host.wait(lambda e: e["type"] == "DDATA" and e["device"] == "line", what="line's DDATA", since=mark)
        assert [(m["name"], m["value"], m["historical"]) for m in t01_data["metrics"]] == [("iBM", 7, False)]
        assert [(m["name"], m["value"]) for m in line_data["metrics"]] == [("heading", -300), ("label", "wörld")]
        assert all(m["timestamp"] and m["properties"] == {} for m in line_data["metrics"])  # no Quality: good all along

        mark = host.mark()
        runtime.db.submit_quality(["total"], Quality.BAD, PROGRAM)
        bad = await host.wait(lambda e: e["type"] == "DDATA" and e["device"] == "line", what="the BAD quality", since=mark)
        assert [(m["name"], m["properties"]) for m in bad["metrics"]] == [("total", {"Quality": 0})]
        mark = host.mark()
        runtime.db.submit([("total", 2.5)], PROGRAM)  # a program's value: good again
        good = await host.wait(lambda e: e["type"] == "DDATA" and e["device"] == "line", what="GOOD again", since=mark)
        assert [(m["name"], m["value"], m["properties"]) for m in good["metrics"]] == [("total", 2.5, {"Quality": 192})]

        status = runtime.db.snapshot(["_sys.sparkplug.state", "_sys.sparkplug.connected", "_sys.sparkplug.births"])
        assert status == {"_sys.sparkplug.state": "online", "_sys.sparkplug.connected": True, "_sys.sparkplug.births": 1}
    finally:
        await runtime.stop()
    await host.wait(lambda e: e["type"] == "NDEATH", what="the NDEATH on stop")
    assert [e["device"] for e in host.of("DDEATH")] == ["t01", "t02", "panel", "line"]
    assert host.of("NDEATH")[-1]["bdSeq"] == 0
    check_seq(host.events, "line1")
    host.close()


async def test_rebirth_and_dcmd_writes_go_through_the_rules_roles_and_audit(mosquitto, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    host = await SparkplugHost.start(mosquitto.port, "plant1")
    # A retained command waits at the broker: the edge node gets it as it subscribes, from an earlier moment.
    await host.send({"op": "dcmd", "node": "line1", "device": "t01", "metrics": [{"name": "iBM", "datatype": "UINT16", "value": 56}], "retain": True})
    writes: list[WriteEvent] = []
    calls: list[Any] = []

    def listen(runtime: Runtime) -> None:
        runtime.db.on_write(writes.extend)
        runtime.commands.on_call(calls.append)

    runtime = await start_plant(tmp_path, mosquitto.port, before=listen)
    try:
        await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", what="the births")
        await _until(lambda: len(writes) == 1)
        assert (writes[0].tag, writes[0].rule) == ("t01_iBM", Rule.INVALID_REQUEST) and "retained" in writes[0].detail
        await host.send({"op": "raw", "topic": "spBv1.0/plant1/DCMD/line1/t01", "hex": "", "retain": True})  # clears it
        del writes[:]
        iBM_alias = metric(birth_of(host, "t01"), "iBM")["alias"]

        async def dcmd(device: str, *metrics: dict[str, Any], **options: Any) -> list[WriteEvent]:
            before = len(writes)
            await host.send({"op": "dcmd", "node": "line1", "device": device, "metrics": list(metrics), **options})
            await _until(lambda: len(writes) >= before + len(metrics))
            return writes[before:]

        # A valid write, by name and by alias: applied at the next scan, audited with the sparkplug origin.
        mark = host.mark()
        [event] = await dcmd("t01", {"name": "iFr", "datatype": "FLOAT", "value": 20.0})
        assert event.accepted and (event.origin.source, event.origin.user, event.origin.role.value) == ("sparkplug", "sparkplug-host", "operator")
        data = await host.wait(lambda e: e["type"] == "DDATA" and e["device"] == "t01", since=mark, what="the written value back")
        assert [(m["name"], m["value"]) for m in data["metrics"]] == [("iFr", 20.0)]
        [event] = await dcmd("t01", {"alias": iBM_alias, "datatype": "UINT16", "value": 12})
        assert event.accepted and event.tag == "t01_iBM"

        # Refused, each with the tag database's rule; nothing changes.
        [event] = await dcmd("t01", {"name": "iFr", "datatype": "FLOAT", "value": 7000.0})
        assert (event.rule, event.tag) == (Rule.OUT_OF_RANGE, "t01_iFr")
        [event] = await dcmd("t01", {"name": "iBL", "datatype": "FLOAT", "value": 5.0})
        assert event.rule is Rule.READ_ONLY
        [event] = await dcmd("panel", {"name": "panel_setpoint", "datatype": "DOUBLE", "value": 1.0})
        assert event.rule is Rule.ACCESS_DENIED and event.origin.role.value == "viewer"
        [event] = await dcmd("t01", {"name": "iFr", "datatype": "BOOLEAN", "value": True}, dtypes=True)
        assert event.rule is Rule.TYPE_MISMATCH and "datatype Boolean, but 'iFr' is Float" in event.detail
        unknown, valid = await dcmd("t01", {"name": "iFx", "datatype": "FLOAT", "value": 1.0}, {"name": "iBM", "datatype": "UINT16", "value": 99})
        assert (unknown.rule, unknown.tag) == (Rule.UNKNOWN_TAG, "t01/iFx") and "did you mean 'iFr'" in unknown.detail
        assert valid.rule is not None and valid.detail.startswith("not applied: t01/iFx")  # never half a command
        [event] = await dcmd("t01", {"alias": 9999, "datatype": "UINT16", "value": 1})
        assert (event.rule, event.tag) == (Rule.UNKNOWN_TAG, "t01/alias 9999")
        [event] = await dcmd("t01", {"name": "iBM", "datatype": "UINT16", "value": 55}, timestamp=int(time.time() * 1000) - 3_600_000)
        assert event.rule is Rule.INVALID_REQUEST and "from a time the edge node was dead" in event.detail
        await _tick(0.2)
        assert runtime.db.snapshot(["t01_iFr", "t01_iBM", "t01_iBL", "panel_setpoint"]) == {
            "t01_iFr": 20.0, "t01_iBM": 12, "t01_iBL": 0.0, "panel_setpoint": 0.0}

        # An NCMD may only ask for a rebirth: the node's bdSeq and unknown metrics are refused.
        ncmd = pb.Payload(timestamp=int(time.time() * 1000))
        ncmd.metrics.add(name="bdSeq", datatype=4, long_value=7)
        ncmd.metrics.add(name="Node Control/Reboot", datatype=11, boolean_value=True)
        before = len(writes)
        await host.send({"op": "raw", "topic": "spBv1.0/plant1/NCMD/line1", "hex": ncmd.SerializeToString().hex()})
        await _until(lambda: len(writes) >= before + 2)
        assert [(w.tag, w.rule) for w in writes[before:]] == [("bdSeq", Rule.READ_ONLY), ("line1/Node Control/Reboot", Rule.UNKNOWN_TAG)]

        # Bytes that are no payload, many times: refused and audited each time, logged once.
        caplog.set_level(logging.WARNING, logger="softplc.adapters.sparkplug.commands")
        logged_before = len(caplog.records)
        for _ in range(20):
            await host.send({"op": "raw", "topic": "spBv1.0/plant1/DCMD/line1/t02", "hex": "ffffffff"})
        await _until(lambda: sum(call.command == "sparkplug.DCMD" for call in calls) >= 20)
        refusal = next(call for call in calls if call.command == "sparkplug.DCMD")
        assert not refusal.accepted and "not a Sparkplug B payload" in refusal.detail and refusal.origin.source == "sparkplug"
        lines = [r for r in caplog.records[logged_before:] if r.name == "softplc.adapters.sparkplug.commands"]
        assert len(lines) == 1, [r.getMessage() for r in lines]  # logged once; the rest counted for the summary

        # Rebirth: births again, same bdSeq (same MQTT session), seq from 0; audited as a command.
        mark = host.mark()
        await host.send({"op": "rebirth", "node": "line1"})
        nbirth = await host.wait(lambda e: e["type"] == "NBIRTH", since=mark, what="the NBIRTH after Rebirth")
        assert (nbirth["seq"], nbirth["bdSeq"]) == (0, 0)
        await host.wait(lambda e: e["type"] == "DBIRTH" and e["device"] == "line", since=mark, what="the DBIRTHs after Rebirth")
        assert metric(birth_of(host, "t01"), "iFr")["value"] == 20.0
        assert any(call.command == "sparkplug.rebirth" and call.accepted for call in calls)
        await _until(lambda: runtime.db.value("_sys.sparkplug.births") == 2 and runtime.db.value("_sys.sparkplug.refused") >= 31)
        assert "not a Sparkplug B payload" in runtime.db.value("_sys.sparkplug.last_refusal")
        check_seq(host.events, "line1")
    finally:
        await runtime.stop()
        host.close()


async def _tick(seconds: float = 0.02) -> None:
    import asyncio

    await asyncio.sleep(seconds)


async def _until(condition: Any, timeout: float = 5.0) -> None:
    import asyncio

    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.02)
