"""NCMD and DCMD: commands from Sparkplug host applications, checked whole before anything is applied.

A DCMD writes tags of one device; it goes through `plant.tags.submit(..., atomic=True)` with
an origin `sparkplug:<user>@<broker>` and the device's role, so the tag database's validation
(type, range, read-only, forced), the roles and the audit trail apply as to any other client.
An NCMD may only ask for a rebirth (`Node Control/Rebirth` = true), which any host may.

A message is refused whole — nothing of it applied — when it is not a Sparkplug payload, has no
timestamp, was retained by the broker, arrives while the node is not born, was sent before the
current birth (from a time the node was dead: aimed at an earlier session), or when one of its
metrics is unknown (name or alias), has the wrong datatype or no value. Each refusal is
audited (a write refused with its rule; an unreadable message as a refused `sparkplug.DCMD`
command), counted in `_sys.sparkplug.refused` and logged once per topic and 10 s.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from softplc.adapters.sparkplug.settings import Device, SparkplugSettings
from softplc.adapters.sparkplug.status import Status
from softplc.core.plant import Plant
from softplc.core.tagdb import Origin, Rule
from softplc.protocols.sparkplug import payloads
from softplc.protocols.sparkplug.metrics import BD_SEQ, REBIRTH
from softplc.protocols.sparkplug.topics import command_target
from softplc.util.peers import PeerLog
from softplc.util.suggest import did_you_mean

log = logging.getLogger(__name__)


class Session(Protocol):
    """What the command door asks of the edge node's session."""

    born: bool
    birth_timestamp: int  # ms since the epoch of the current NBIRTH

    def request_rebirth(self, origin: Origin) -> None: ...


@dataclass
class _Item:
    """One metric of a command, resolved as far as it goes."""

    label: str  # what the audit trail calls it: the tag, or device/metric when unknown
    tag: str | None = None
    value: Any = None
    rule: Rule | None = None
    detail: str = ""


class CommandDoor:
    """Handles every NCMD and DCMD of this edge node (`handle` is the MQTT subscription's handler)."""

    def __init__(self, plant: Plant, settings: SparkplugSettings, session: Session, status: Status, peer: str,
                 now_ms: Callable[[], int]) -> None:
        self.plant = plant
        self.settings = settings
        self.session = session
        self.status = status
        self.peer = peer  # the broker, host:port: where commands come from
        self.now_ms = now_ms
        self.devices = {device.id: device for device in settings.devices}
        self.peer_log = PeerLog(log, service="Sparkplug B")

    def origin(self, device: Device | None) -> Origin:
        return Origin("sparkplug", user=self.settings.user, peer=self.peer, role=device.role if device else self.settings.role)

    def handle(self, topic: str, raw: bytes, retained: bool) -> None:
        target = command_target(topic, self.settings.group_id, self.settings.edge_node_id)
        if target is None:
            return
        kind, device_id = target
        if not raw:
            return  # a zero-length message clears a retained one at the broker: no command
        device = self.devices.get(device_id) if device_id is not None else None
        origin = self.origin(device)
        if kind == "DCMD" and device is None:
            self._refuse_message(kind, topic, origin, f"no device '{device_id}' on edge node {self.settings.edge_node_id}"
                                 f"{did_you_mean(str(device_id), self.devices)}")
            return
        try:
            payload = payloads.decode(raw)
        except payloads.MalformedPayload as error:
            self._refuse_message(kind, topic, origin, str(error))
            return
        if not payload.metrics:
            self._refuse_message(kind, topic, origin, "a command without metrics")
            return
        items = [self._resolve(device, metric) for metric in payload.metrics]
        reason = self._stale(payload, retained)
        if reason is not None:
            self._refuse(topic, origin, items, reason, Rule.INVALID_REQUEST)
            return
        first = next((item for item in items if item.rule is not None), None)
        if first is not None:
            self._refuse(topic, origin, items, f"{first.label}: {first.detail}", first.rule)
            return
        if device is None:
            self.session.request_rebirth(origin)
            self.status.commands += len(items)
            return
        results = self.plant.tags.submit([(item.tag, item.value) for item in items], origin, atomic=True)
        refusal = next((result for result in results if result is not None), None)
        if refusal is not None:  # the tag database audited each item already
            self._count_refusal(topic, len(items), str(refusal))
            return
        self.status.commands += len(items)

    # -- checks --------------------------------------------------------------------------------

    def _stale(self, payload: Any, retained: bool) -> str | None:
        """Why the whole message must not be applied, whatever its metrics."""
        if retained:
            return "a retained command (kept by the broker from an earlier moment; Sparkplug commands are never retained)"
        if not payload.HasField("timestamp"):
            return "the payload has no timestamp (Sparkplug 3.0.0 requires one in every command)"
        if not self.session.born:
            return "the edge node is not online (no birth in this session): the host cannot know its metrics"
        earliest = self.session.birth_timestamp - round(self.settings.clock_tolerance * 1000)
        if payload.timestamp < earliest:
            return (f"sent at {payload.timestamp} ms, before this session's birth at {self.session.birth_timestamp} ms: "
                    f"from a time the edge node was dead")
        return None

    def _resolve(self, device: Device | None, metric: Any) -> _Item:
        """The tag and value of one metric of a command, or why it cannot be applied."""
        if device is None:  # NCMD: the node's own metrics
            name = metric.name if metric.HasField("name") else f"alias {metric.alias}"
            if metric.name == REBIRTH:
                if metric.WhichOneof("value") == "boolean_value" and metric.boolean_value:
                    return _Item(REBIRTH)
                return _Item(REBIRTH, rule=Rule.TYPE_MISMATCH, detail="a rebirth request is the Boolean true")
            if metric.name == BD_SEQ:
                return _Item(BD_SEQ, rule=Rule.READ_ONLY, detail="bdSeq is the edge node's own")
            return _Item(f"{self.settings.edge_node_id}/{name}", rule=Rule.UNKNOWN_TAG,
                         detail=f"the edge node has no metric {name!r}; its commands: {REBIRTH}")
        if metric.HasField("alias"):
            found = next(((tag, d) for tag, d in device.metrics.items() if d.alias == metric.alias), None)
            wanted = f"alias {metric.alias}"
        else:
            found = device.by_name.get(metric.name)
            wanted = repr(metric.name)
        if found is None:
            hint = did_you_mean(metric.name, [d.name for d in device.metrics.values()]) if not metric.HasField("alias") else ""
            return _Item(f"{device.id}/{metric.name or wanted}", rule=Rule.UNKNOWN_TAG,
                         detail=f"device {device.id} has no metric {wanted}{hint}")
        tag, definition = found
        try:
            value = payloads.command_value(definition, metric)
        except payloads.CommandValueError as error:
            return _Item(tag, tag=tag, rule=Rule.TYPE_MISMATCH if error.wrong_type else Rule.INVALID_REQUEST, detail=str(error))
        return _Item(tag, tag=tag, value=value)

    # -- refusals ------------------------------------------------------------------------------

    def _refuse(self, topic: str, origin: Origin, items: list[_Item], reason: str, rule: Rule | None) -> None:
        """Nothing of the message is applied: every metric is audited as refused, the others 'not applied'."""
        for item in items:
            if item.rule is not None:
                self.plant.tags.refused(origin, item.label, item.value, item.rule, item.detail)
            else:
                self.plant.tags.refused(origin, item.label, item.value, rule or Rule.INVALID_REQUEST, f"not applied: {reason}")
        self._count_refusal(topic, len(items), reason)

    def _refuse_message(self, kind: str, topic: str, origin: Origin, reason: str) -> None:
        """A message with no metric to name: audited as a refused command."""
        self.plant.commands.refused(f"sparkplug.{kind}", {"topic": topic}, origin, reason)
        self._count_refusal(topic, 1, reason)

    def _count_refusal(self, topic: str, count: int, reason: str) -> None:
        self.status.refused += count
        self.status.last_refusal = f"{topic}: {reason}"[:500]
        self.peer_log.warning(topic, "refused commands", "Sparkplug B: command on %s refused: %s", topic, reason)
