"""The Sparkplug B edge node adapter: the plant's tags published over MQTT (docs/sparkplug.md).

One MQTT connection of its own (`softplc.protocols.mqtt`, client id `…-sparkplug`), whose last
will is the NDEATH with this session's bdSeq. After each connect — and, with a primary host,
once its STATE says online — it publishes the NBIRTH (seq 0) and one DBIRTH per device, then
data by exception: the tags that changed are collected by `plant.tags.on_change`, and at each
scan boundary (`plant.after_cycle`) one publisher turn sends one DDATA per device with them.

While it cannot deliver (no broker, or the primary host offline) the data goes to the store
(`store.py`) and is forwarded, flagged historical, after the next births. When the primary host
goes offline it publishes its NDEATH and reconnects (Sparkplug 3.0.0 §5.6); on stop, a DDEATH
per device and the NDEATH, then a clean disconnect. Commands: `commands.py`.

Everything it sends is built and numbered by one coroutine (the publisher), so seq is in the
order of the messages on the wire.

In a redundant pair both members are the same edge node, so only the active has a session: the
standby connects nothing (no will, no births), and takes the active's bdSeq with every state
it mirrors (`plant.replicate`), so its first session after a takeover is numbered after the
old active's — the old session's late will (a frozen active's) can never kill the new births.
A member that stops being active publishes its NDEATH and disconnects (docs/redundancy.md).
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from softplc.adapters.sparkplug import status as states
from softplc.adapters.sparkplug.changes import Changes, Held, Pending
from softplc.adapters.sparkplug.commands import CommandDoor
from softplc.adapters.sparkplug.settings import Device, SparkplugSettings
from softplc.adapters.sparkplug.status import Status
from softplc.adapters.sparkplug.store import Store
from softplc.core.commands import CommandRefused, Permission
from softplc.core.plant import Plant, StateRefused
from softplc.core.plant_role import PlantRole, RoleTerm
from softplc.core.tagdb import Origin
from softplc.protocols.mqtt import MqttConnection, NotConnected, Will
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.protocols.sparkplug import payloads
from softplc.protocols.sparkplug.sequence import BirthDeathSequence, MessageSequence
from softplc.protocols.sparkplug.topics import HostState, device_topic, node_topic, parse_state, state_topic
from softplc.util.peers import PeerLog
from softplc.util.tasks import cancel_and_wait, within

log = logging.getLogger(__name__)

FORWARD_BATCH = 20  # historical messages between two looks at live data waiting
HOLD_PERIOD = 1.0  # seconds of changes gathered into one stored message per device while offline
HOLD_LIMIT = 5000  # changes gathered at most before they go to the store anyway
STATUS_PERIOD = 1.0  # seconds between refreshes of the counters in _sys.sparkplug.*


class EdgeNode:
    """The `sparkplug` adapter (see the module docstring)."""

    name = "sparkplug"

    def __init__(self, settings: SparkplugSettings, mqtt: MqttSettings) -> None:
        self.settings = settings
        self.mqtt = mqtt
        self.status = Status()
        self.born = False
        self.birth_timestamp = 0
        self.bd_seq = 0  # of the current session (the will registered at its CONNECT)
        self.seq = MessageSequence()
        self.changes = Changes(settings.devices)
        self._definitions = {device.id: {d.name: d for d in device.metrics.values()} for device in settings.devices}
        self._devices = {device.id: device for device in settings.devices}
        self._held: Held = []  # changes while offline, gathered for the store
        self._held_since = 0.0
        self._wake = asyncio.Event()
        self._rebirth = False
        self._host: HostState | None = None  # the primary host's last valid STATE
        self._host_lost = False  # it went offline while we were born: NDEATH and reconnect
        self._stopping = False
        self._dropped = 0  # data messages lost (no store, or it failed)
        self._undo: list[Any] = []
        self._tasks: list[asyncio.Task[Any]] = []
        self.store: Store | None = None
        self.peer_log = PeerLog(log, service="Sparkplug B")

    # -- the adapter ---------------------------------------------------------------------------

    async def start(self, plant: Plant) -> None:
        self.plant = plant
        settings = self.settings
        state_dir = settings.state_dir(plant.state_dir)
        self.sequence_file = BirthDeathSequence(state_dir / "bdseq")
        if settings.store_enabled:
            self.store = Store(state_dir / "store", settings.store_max_size)
            await plant.clock.run_blocking(self.store.open)
        self.door = CommandDoor(plant, settings, self, self.status, f"{self.mqtt.host}:{self.mqtt.port}", self.now_ms)
        self._undo = [
            plant.tags.on_change(self.changes.note),
            plant.after_cycle(lambda task: self._wake.set() if self.changes.pending else None),
            plant.commands.register("sparkplug.rebirth", self._rebirth_command, permission=Permission.VIEW, audited=True,
                                    description="publish the Sparkplug B births again"),
            plant.commands.register("sparkplug.status", lambda arguments, origin: self.describe_state(), permission=Permission.VIEW,
                                    description="the Sparkplug B edge node's connection and primary host state"),
            plant.role.on_change(self._role_changed),
            plant.replicate("sparkplug", self._capture_bd_seq, _check_bd_seq, self.sequence_file.follow),
        ]
        self.status.running = True
        self.status.primary_host_online = not settings.primary_host
        self._tasks = [plant.spawn(self._publisher(), "sparkplug publisher"),
                       plant.spawn(self._status_loop(), "sparkplug status")]
        self._session: asyncio.Task[None] | None = None
        self._captured_bd_seq = -1
        if plant.role.term.role is PlantRole.ACTIVE:
            self._open()
        else:
            self.status.state = states.STANDBY
        self._refresh()

    def _open(self) -> None:
        """A session with the broker (this member is active): its will, its subscriptions, then births."""
        settings = self.settings
        self.connection = MqttConnection(self.mqtt, self.plant.role.own("sparkplug"), self.plant.clock, will=self._will,
                                         clean_start=True)
        self.connection.on_state(self._connection_changed)
        self.connection.subscribe(node_topic(settings.group_id, "NCMD", settings.edge_node_id), self.door.handle, qos=1)
        self.connection.subscribe(device_topic(settings.group_id, "DCMD", settings.edge_node_id, "+"), self.door.handle, qos=1)
        if settings.primary_host:
            self.connection.subscribe(state_topic(settings.primary_host), self._host_state, qos=1)
        self.status.state = states.CONNECTING
        self._session = self.plant.spawn(self.connection.run(), "sparkplug connection")

    async def _close(self) -> None:
        """End the session: the DDEATHs and NDEATH if born, then a clean disconnect."""
        if self._session is None:
            return
        session, self._session = self._session, None
        if self.born:
            try:
                now = self.now_ms()
                for device in self.settings.devices:
                    await self._send(device_topic(self.settings.group_id, "DDEATH", self.settings.edge_node_id, device.id),
                                     payloads.encode_device_death(now, self.seq.next()))
                await self.connection.publish(self._topic("NDEATH"), payloads.encode_node_death(self.bd_seq, now), qos=1)
            except NotConnected:
                pass
        self.born = False
        await self.connection.close()
        await cancel_and_wait([session])

    def _role_changed(self, term: RoleTerm) -> None:
        """In a redundant pair: a session while active, none otherwise (both members are one edge node)."""
        if self._stopping:
            return
        if term.role is PlantRole.ACTIVE and self._session is None:
            log.info("Sparkplug B: this member is active (epoch %d): connecting as edge node %s/%s", term.epoch,
                     self.settings.group_id, self.settings.edge_node_id)
            self.changes.take()  # the births carry the current values
            self._open()
        self._refresh()
        self._wake.set()  # the publisher ends the session of a member no longer active (it numbers every message sent)

    def _capture_bd_seq(self, full: bool) -> int | None:
        """The active's bdSeq for its standby (None: unchanged since the last capture)."""
        value = self.sequence_file.value
        if not full and value == self._captured_bd_seq:
            return None
        self._captured_bd_seq = value
        return value

    async def stop(self) -> None:
        self._stopping = True
        for undo in self._undo:
            undo()
        self._wake.set()
        publisher = self._tasks[0] if self._tasks else None
        if publisher is not None:
            try:
                await within(5.0, asyncio.shield(publisher))  # let it finish the message it is sending
            except (asyncio.TimeoutError, asyncio.CancelledError):
                publisher.cancel()
        changes = self.changes.take()
        if self.born and self.plant.role.is_active():
            try:
                await self._publish_data(changes)
            except NotConnected:
                pass
        elif self._session is not None:
            self._hold(changes)
            self._flush_held()
        await self._close()
        await cancel_and_wait(self._tasks)
        if self.store is not None:
            self.store.close()
        self.status.running = self.status.connected = False
        self.status.state = states.OFF
        self._refresh()

    def describe(self) -> str:
        host = f", primary host {self.settings.primary_host}" if self.settings.primary_host else ""
        return (f"Sparkplug B edge node {self.settings.group_id}/{self.settings.edge_node_id} on {self.mqtt.url} "
                f"({len(self.settings.devices)} devices, {len(self.changes.metric_of)} metrics{host})")

    def metrics(self) -> dict[str, Any]:
        return self.status.figures()

    def describe_state(self) -> dict[str, Any]:
        """What the `sparkplug.status` query answers."""
        return {"broker": self.mqtt.url, "group_id": self.settings.group_id, "edge_node_id": self.settings.edge_node_id,
                "primary_host": self.settings.primary_host, "devices": {d.id: len(d.metrics) for d in self.settings.devices},
                "bdseq": self.bd_seq, "seq": self.seq.value, **{k: v for k, v in vars(self.status).items() if not k.startswith("_")}}

    def now_ms(self) -> int:
        return round(self.plant.clock.wall() * 1000)

    # -- the session ---------------------------------------------------------------------------

    def _will(self) -> Will:
        self.bd_seq = self.sequence_file.for_connect(self.connection.connects)
        return Will(self._topic("NDEATH"), payloads.encode_node_death(self.bd_seq, self.now_ms()), qos=1, retain=False)

    def _connection_changed(self, up: bool) -> None:
        self.status.connected = up
        if up:
            self.status.bdseq = self.bd_seq
            # The primary host's retained STATE arrives right after the subscription: until then, wait.
            self.status.primary_host_online = not self.settings.primary_host
            self.status.state = states.WAITING if self.settings.primary_host else states.CONNECTING
        else:
            self.born = False
            self._host = self._host if self._host is None else HostState(False, self._host.timestamp)
            self.status.state = states.CONNECTING if self._session is not None else states.STANDBY
        self._refresh()
        self._wake.set()

    def _host_state(self, topic: str, raw: bytes, retained: bool) -> None:
        try:
            state = parse_state(raw)
        except ValueError as error:
            self.peer_log.warning(topic, "bad STATE messages", "Sparkplug B: ignoring the STATE on %s: %s", topic, error)
            return
        if self._host is not None and state.timestamp < self._host.timestamp:
            return  # an older session's STATE (a late will): §5.6, it must be ignored
        self._host = state
        self.status.primary_host_online = state.online
        if not state.online and self.born:
            self._host_lost = True
        if not state.online:
            self.status.state = states.WAITING
        self._refresh()
        self._wake.set()

    def request_rebirth(self, origin: Origin) -> None:
        """An NCMD Rebirth: through the `sparkplug.rebirth` command, so it is audited like any command."""
        async def call() -> None:
            try:
                await self.plant.commands.call("sparkplug.rebirth", {}, origin)
            except CommandRefused as refusal:
                log.info("Sparkplug B: rebirth refused: %s", refusal)

        self.plant.spawn(call(), "sparkplug rebirth")

    def _rebirth_command(self, arguments: Any, origin: Origin) -> str:
        if not self.born:
            raise CommandRefused("the edge node is not online; it publishes its births as soon as it is")
        self._rebirth = True
        self._wake.set()
        return "NBIRTH and DBIRTHs follow"

    # -- data ----------------------------------------------------------------------------------

    async def _publisher(self) -> None:
        while not self._stopping:
            await self._wake.wait()
            self._wake.clear()
            if self._stopping:
                return
            try:
                await self._turn()
            except NotConnected:
                self.born = False  # the session is gone: the next one starts with births
            except Exception:
                log.exception("Sparkplug B: publishing failed; going on")

    async def _turn(self) -> None:
        if self._session is not None and self.plant.role.term.role is not PlantRole.ACTIVE:
            log.info("Sparkplug B: this member is no longer active: NDEATH and disconnect")
            await self._close()
            self.status.state = states.STANDBY
            self._refresh()
        if self._session is None or not self.plant.role.is_active():
            # A standby's changes are the active's, mirrored: the active publishes them. (An active
            # whose term lapsed — frozen, then woken — publishes nothing until it is told its role.)
            self.changes.take()
            return
        connection = self.connection
        if self._host_lost:
            self._host_lost = False
            if self.born:
                await self._die_and_reconnect()
                return
        host_online = not self.settings.primary_host or (self._host is not None and self._host.online)
        if connection.connected and ((not self.born and host_online) or (self.born and self._rebirth)):
            await self._birth()
        changes = self.changes.take()
        if changes:
            if self.born:
                await self._publish_data(changes)
            else:
                self._hold(changes)
        if self.born and self.store is not None and self.store.count:
            await self._forward()
            if self.store.count:
                self._wake.set()  # more to forward at the next turn (live data goes in between)

    async def _birth(self) -> None:
        self._flush_held()  # what changed while offline is forwarded after the births
        self._rebirth = False
        now = self.now_ms()
        self.birth_timestamp = now
        group, node = self.settings.group_id, self.settings.edge_node_id
        self.seq.birth()
        messages = [(self._topic("NBIRTH"), payloads.encode_node_birth(now, self.bd_seq))]
        for device, metrics in self.changes.births(self.plant.tags):  # the current values: nothing left pending
            messages.append((device_topic(group, "DBIRTH", node, device.id),
                             payloads.encode_device_birth(now, self.seq.next(), metrics, properties=self.settings.properties)))
        for topic, payload in messages:
            await self._send(topic, payload)
        self.born = True
        self.status.births += 1
        self.status.state = states.ONLINE
        self._refresh()
        log.info("Sparkplug B: edge node %s/%s born (bdSeq %d, %d devices, %d metrics)", group, node, self.bd_seq,
                 len(self.settings.devices), len(self.changes.metric_of))

    async def _publish_data(self, changes: Pending) -> None:
        """One DDATA per device with its changes; what cannot be sent any more goes to the store."""
        batches = self.changes.batches(changes)
        now = self.now_ms()
        group, node, by_alias = self.settings.group_id, self.settings.edge_node_id, self.settings.aliases
        for index, (device, batch) in enumerate(batches):
            if index:
                # One device's message at a time: a scan cycle due meanwhile runs first (the real
                # clock holds a sleeper waking within 5 ms of a release until that cycle has run).
                await self.plant.clock.sleep(0)
            payload = payloads.encode_data(now, self.seq.next(), batch, by_alias=by_alias)
            try:
                await self._send(device_topic(group, "DDATA", node, device.id), payload)
            except NotConnected:
                for later_device, later_batch in batches[index:]:
                    self._keep(later_device, later_batch)
                raise
            self.status.metrics += len(batch)

    def _hold(self, changes: Pending) -> None:
        """Offline: gather the changes (all of them, in order), into the store once a second."""
        now = self.plant.clock.now()
        if not self._held:
            self._held_since = now
        self._held.extend(changes.items())
        if now - self._held_since >= HOLD_PERIOD or len(self._held) >= HOLD_LIMIT:
            self._flush_held()

    def _flush_held(self) -> None:
        held, self._held = self._held, []
        if held:
            self._keep_all(held)

    def _keep_all(self, changes: Pending | Held) -> None:
        for device, batch in self.changes.batches(changes):
            self._keep(device, batch)

    def _keep(self, device: Device, batch: list[payloads.Change]) -> None:
        """Data that cannot be delivered now: into the store (by name, without seq), or counted as lost."""
        if self.store is None:
            self._dropped += 1
            return
        self.store.append(device.id, payloads.encode_data(self.now_ms(), None, batch, by_alias=False))

    async def _forward(self) -> None:
        """Send the oldest stored messages as historical DDATA, live data in between."""
        assert self.store is not None
        sent = 0
        try:
            for device_id, raw in self.store.oldest():
                definitions = self._definitions.get(device_id)
                if definitions is not None:
                    payload, kept = payloads.as_historical(raw, definitions, self.now_ms(), by_alias=self.settings.aliases)
                    if kept:
                        payload.seq = self.seq.next()
                        await self._send(device_topic(self.settings.group_id, "DDATA", self.settings.edge_node_id, device_id),
                                         payload.SerializeToString())
                        self.status.metrics += kept
                sent += 1
                if self._rebirth or self._host_lost or self._stopping:
                    break
                if sent % FORWARD_BATCH == 0 and self.changes.pending:
                    await self._publish_data(self.changes.take())
        finally:
            self.store.forwarded(sent)

    async def _die_and_reconnect(self) -> None:
        """The primary host went offline: NDEATH, then a new session that waits for it (§5.6)."""
        self.born = False
        self.status.state = states.WAITING
        self._refresh()
        try:
            await self.connection.publish(self._topic("NDEATH"), payloads.encode_node_death(self.bd_seq, self.now_ms()), qos=1)
        except NotConnected:
            return
        await self.connection.restart(f"primary host {self.settings.primary_host} went offline")

    async def _send(self, topic: str, payload: bytes) -> None:
        await self.connection.publish(topic, payload, qos=0)
        self.status.messages += 1

    def _topic(self, message_type: str) -> str:
        return node_topic(self.settings.group_id, message_type, self.settings.edge_node_id)

    # -- status --------------------------------------------------------------------------------

    async def _status_loop(self) -> None:
        while True:
            await self.plant.clock.sleep(STATUS_PERIOD)
            if self._held and self.plant.clock.now() - self._held_since >= HOLD_PERIOD:
                self._flush_held()  # nothing changed for a while: what was gathered goes to disk all the same
            self._refresh()

    def _refresh(self) -> None:
        store = self.store
        self.status.stored = store.count if store is not None else 0
        self.status.dropped = (store.dropped if store is not None else 0) + self._dropped
        self.status.publish(self.plant.tags)


def _check_bd_seq(data: object) -> int:
    """The active's bdSeq as a standby receives it."""
    if not isinstance(data, int) or isinstance(data, bool) or not 0 <= data <= 255:
        raise StateRefused(f"sparkplug: bdSeq {data!r} is not a number 0..255")
    return data
