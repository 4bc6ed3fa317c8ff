"""An independent Sparkplug B host application for the tests: pysparkplug 0.6.1 on paho-mqtt 1.6.

It runs in a virtualenv of its own (tests/sparkplug/.venv, made by scripts/install-test-tools.sh:
pysparkplug needs paho-mqtt < 2, softplc's aiomqtt needs paho-mqtt 2). It decodes what an edge
node publishes with pysparkplug's own payload classes (aliases resolved from the births it saw)
and prints one JSON line per message; it reads commands as JSON lines on stdin:

    {"op": "state", "online": true}                      publish its STATE (retained, QoS 1)
    {"op": "rebirth", "node": "line1"}                   NCMD Node Control/Rebirth = true
    {"op": "dcmd", "node": "line1", "device": "t01", "metrics": [{"name": "iFr", "datatype": "FLOAT", "value": 20.0}]}
    {"op": "raw", "topic": "...", "hex": "0a0b", "retain": false}    any bytes
    {"op": "quit"}

    python host.py --port 1883 --group plant1 [--host-id scada]
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

import paho.mqtt.client as paho
import pysparkplug as sp
from pysparkplug import _protobuf as protobuf  # the generated module pysparkplug ships

out_lock = threading.Lock()


def emit(event: dict[str, Any]) -> None:
    with out_lock:
        sys.stdout.write(json.dumps(event) + "\n")
        sys.stdout.flush()


def properties_of(raw: bytes) -> list[dict[str, Any]]:
    """Each metric's property set (pysparkplug's Metric leaves them out): key → value."""
    payload = protobuf.Payload.FromString(raw)
    found = []
    for metric in payload.metrics:
        values = {}
        for key, value in zip(metric.properties.keys, metric.properties.values):
            field = value.WhichOneof("value")
            values[key] = getattr(value, field) if field else None
        found.append(values)
    return found


def plain(value: Any) -> Any:
    return value if isinstance(value, (bool, int, float, str)) or value is None else repr(value)


class Host:
    def __init__(self, arguments: argparse.Namespace) -> None:
        self.arguments = arguments
        self.births: dict[tuple[str | None, str | None, str | None], Any] = {}
        self.client = paho.Client(client_id=f"test-host-{arguments.host_id or 'plain'}", clean_session=True)
        self.connect_time = int(time.time() * 1000)
        self.went_offline = False
        if arguments.host_id:
            will = sp.State(timestamp=self.connect_time, online=False)
            self.client.will_set(f"spBv1.0/STATE/{arguments.host_id}", will.encode(), qos=1, retain=True)
        self.client.on_connect = self.connected
        self.client.on_message = self.received
        self.client.reconnect_delay_set(min_delay=1, max_delay=2)

    def connected(self, client: paho.Client, userdata: Any, flags: Any, rc: int) -> None:
        self.births.clear()
        client.subscribe(f"spBv1.0/{self.arguments.group}/#", qos=1)
        emit({"type": "ready", "rc": rc})

    def received(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        try:
            topic = sp.Topic.from_str(message.topic)
            if topic.message_type in (sp.MessageType.NCMD, sp.MessageType.DCMD, sp.MessageType.STATE):
                return  # commands (ours, echoed by the broker) are not the edge node's
            key = (topic.group_id, topic.edge_node_id, topic.device_id)
            decoded = sp.Message.from_mqtt_message(message, birth=self.births.get(key))
            payload = decoded.payload
            kind = str(topic.message_type.value if hasattr(topic.message_type, "value") else topic.message_type)
            event: dict[str, Any] = {"type": kind, "node": topic.edge_node_id, "device": topic.device_id, "retain": message.retain,
                                     "received": int(time.time() * 1000)}
            if isinstance(payload, sp.NDeath):
                event["bdSeq"] = payload.bd_seq_metric.value
                event["metrics"] = [{"name": payload.bd_seq_metric.name, "value": payload.bd_seq_metric.value}]
            elif isinstance(payload, (sp.NBirth, sp.DBirth, sp.NData, sp.DData, sp.DDeath)):
                event["seq"] = payload.seq
                event["timestamp"] = payload.timestamp
                metrics = getattr(payload, "metrics", ())
                properties = properties_of(message.payload) if metrics else []
                event["metrics"] = [
                    {"name": metric.name, "alias": metric.alias, "datatype": metric.datatype.name, "value": plain(metric.value),
                     "historical": metric.is_historical, "timestamp": metric.timestamp, "properties": props}
                    for metric, props in zip(metrics, properties)]
                if isinstance(payload, sp.NBirth):
                    event["bdSeq"] = next(m.value for m in metrics if m.name == "bdSeq")
                if isinstance(payload, (sp.NBirth, sp.DBirth)):
                    self.births[key] = payload
            else:
                return
            emit(event)
        except Exception as error:  # a payload pysparkplug cannot read is a finding of the test
            emit({"type": "error", "topic": message.topic, "error": f"{type(error).__name__}: {error}"})

    def command(self, line: dict[str, Any]) -> bool:
        group = self.arguments.group
        now = line.get("timestamp", int(time.time() * 1000))
        op = line["op"]
        if op == "quit":
            return False
        if op == "state":
            # Online carries the timestamp of the will registered at connect (§5.4), so a will can
            # never be taken for a newer session's death; back online after going offline, a new one.
            online = bool(line["online"])
            if online and "timestamp" not in line:
                now = self.connect_time if not self.went_offline else now
            self.went_offline = self.went_offline or not online
            state = sp.State(timestamp=now, online=online)
            self.client.publish(f"spBv1.0/STATE/{self.arguments.host_id}", state.encode(), qos=1, retain=True).wait_for_publish()
        elif op == "rebirth":
            metric = sp.Metric(timestamp=now, name="Node Control/Rebirth", datatype=sp.DataType.BOOLEAN, value=True)
            payload = sp.NCmd(timestamp=now, metrics=(metric,))
            self.client.publish(f"spBv1.0/{group}/NCMD/{line['node']}", payload.encode(include_dtypes=True), qos=0).wait_for_publish()
        elif op == "dcmd":
            metrics = tuple(sp.Metric(timestamp=now, name=m.get("name"), alias=m.get("alias"), datatype=sp.DataType[m["datatype"]],
                                      value=m["value"]) for m in line["metrics"])
            payload = sp.DCmd(timestamp=now, metrics=metrics)
            self.client.publish(f"spBv1.0/{group}/DCMD/{line['node']}/{line['device']}", payload.encode(include_dtypes=line.get("dtypes", False)),
                                qos=0, retain=bool(line.get("retain", False))).wait_for_publish()
        elif op == "raw":
            self.client.publish(line["topic"], bytes.fromhex(line["hex"]), qos=0, retain=bool(line.get("retain", False))).wait_for_publish()
        emit({"type": "done", "op": op, "id": line.get("id")})
        return True

    def run(self) -> None:
        self.client.connect("127.0.0.1", self.arguments.port, keepalive=5)
        self.client.loop_start()
        for text in sys.stdin:
            if text.strip() and not self.command(json.loads(text)):
                break
        self.client.disconnect()
        self.client.loop_stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--group", required=True)
    parser.add_argument("--host-id", default="")
    Host(parser.parse_args()).run()


if __name__ == "__main__":
    main()
