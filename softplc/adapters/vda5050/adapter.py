"""The VDA 5050 master control adapter: one MQTT connection, every vehicle's messages in, orders and instant actions out.

What comes from the wire is checked before anything is believed: a topic of a vehicle not in
robots.yaml, a message whose header names another vehicle than its topic, a payload that is not
JSON or not a valid state (softplc.protocols.vda5050.validation) is dropped with a rate-limited
log line and shown as the vehicle's error (an alarm) — never a crash, a stalled scan or a wrong
pose. What the master sends is checked against the closed JSON Schemas first (a message that
fails is not sent, and counted: `schema_violations` must stay 0).
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import time
from typing import TYPE_CHECKING, Any

from softplc.adapters.vda5050.commands import register_commands
from softplc.adapters.vda5050.control import MasterControl
from softplc.adapters.vda5050.section import BROKER_TAG
from softplc.adapters.vda5050.settings import VdaSettings
from softplc.adapters.vda5050.vehicle import VehicleLink
from softplc.core.tagdb import Origin
from softplc.protocols.mqtt import MqttConnection, NotConnected
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.protocols.vda5050 import topics
from softplc.protocols.vda5050.messages import FactsheetSummary, VehicleState
from softplc.protocols.vda5050.validation import MessageError, decode, parse_json, problems
from softplc.robotics.roadmap import Roadmap
from softplc.robotics.robots import DriverKind, RobotFile
from softplc.util.peers import PeerLog
from softplc.util.tasks import cancel_and_wait

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

TURN = 4  # orders sent between two looks at the scan's next release
TURN_SECONDS = 0.001  # real seconds of reading the vehicles' messages between two looks at it
MAX_MESSAGE = 1024 * 1024  # bytes: a vehicle's state is a few kB; a bigger message is refused and shown as its error
MAX_RECEIVED = 64 * 1024 * 1024  # bytes the connection hands on at all (beyond: dropped there, logged, not attributed)
ROBOT_TAGS = ("xpos", "ypos", "heading", "speed", "navstate", "navreason", "route", "status", "xgoal", "ygoal", "online")
FACTSHEET_FIELDS = (("length_mm", "length"), ("width_mm", "width"), ("height_mm", "height"), ("max_linear_speed", "speedMax"),
                    ("max_angular_speed", "angularSpeedMax"), ("load_capacity", "maxLoadMass"))


class VdaMaster:
    """See the module docstring and softplc.adapters.vda5050."""

    name = "vda5050"

    def __init__(self, settings: VdaSettings, mqtt: MqttSettings, robots: RobotFile, roadmap: Roadmap) -> None:
        self.settings = settings
        self.mqtt = mqtt
        self.robots = robots
        self.roadmap = roadmap
        self.vehicles = [robot for robot in robots if robot.driver is DriverKind.VDA5050]
        self.links: dict[str, VehicleLink] = {}
        self.control: MasterControl | None = None
        self.connection: MqttConnection | None = None
        self.plant: Plant | None = None
        self.sent = 0
        self.schema_violations = 0
        self.bad_messages = 0
        self.factsheet_differences: dict[str, list[str]] = {}
        self._by_topic: dict[tuple[str, str], VehicleLink] = {}
        self._tasks: list[asyncio.Task[Any]] = []
        self._undo: list[Any] = []
        self._wire_log = PeerLog(log, service="VDA 5050")
        self._inbox: collections.deque[tuple[str, bytes, float]] = collections.deque(maxlen=100_000)
        self._mail = asyncio.Event()

    # -- adapter protocol ------------------------------------------------------------------------------

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        self.plant = plant
        db = plant.tags
        missing = [f"{robot.id}_{name}" for robot in self.vehicles for name in ROBOT_TAGS if f"{robot.id}_{name}" not in db]
        if missing:
            raise AdapterError(f"vda5050: the VDA 5050 robots of {self.robots.path} need tags tagdb.yaml does not declare: "
                               f"{', '.join(missing[:8])} (the robot template: see docs/vda5050.md)")
        for robot in self.vehicles:
            link = VehicleLink(robot, self.settings.version, db)
            self.links[robot.id] = link
            assert robot.vehicle is not None
            self._by_topic[(robot.vehicle.manufacturer, robot.vehicle.serial_number)] = link
            link.go_offline("no state yet")
        self.control = MasterControl(self.roadmap, self.settings, self.links, db)
        db.submit([(f"{robot.id}_radius", robot.radius) for robot in self.vehicles if f"{robot.id}_radius" in db],
                  Origin("vda5050", role=None))
        connection = self.connection = MqttConnection(self.mqtt, plant.role.own("vda5050"), plant.clock, max_payload=MAX_RECEIVED)
        interface, version = self.settings.interface, self.settings.version
        for name in (topics.STATE, topics.CONNECTION, topics.FACTSHEET):
            connection.subscribe(topics.vehicle_filter(interface, version, name), self._receive, qos=1 if name == topics.CONNECTION else 0)
        self._undo.append(connection.on_state(self._on_broker))
        self._undo += register_commands(plant.commands, self)
        self._tasks = [plant.spawn(connection.run(), "vda5050-mqtt"), plant.spawn(self._run(), "vda5050-master"),
                       plant.spawn(self._read(), "vda5050-inbox")]

    async def stop(self) -> None:
        await cancel_and_wait(self._tasks)
        self._tasks.clear()
        if self.connection is not None:
            await self.connection.close()
        for undo in self._undo:
            undo()
        self._undo.clear()
        if self.control is not None:
            self.control.close()

    def describe(self) -> str:
        return (f"VDA 5050 {self.settings.version} master control of {len(self.vehicles)} vehicles on {self.mqtt.url} "
                f"(roadmap {self.roadmap.path.name}: {len(self.roadmap.nodes)} nodes, {len(self.roadmap.lanes)} lane directions)")

    def metrics(self) -> dict[str, Any]:
        control = self.control
        return {
            "vehicles_alive": sum(1 for link in self.links.values() if link.alive),
            "messages_sent": self.sent, "schema_violations": self.schema_violations, "bad_messages": self.bad_messages,
            "order_resends": sum(link.trip.resends for link in self.links.values() if link.trip is not None),
            "reservation_conflicts": control.traffic.conflicts if control else 0,
            "deadlocks_broken": control.deadlocks_broken if control else 0,
        }

    # -- the master's loop --------------------------------------------------------------------------------------

    async def _run(self) -> None:
        assert self.plant is not None and self.control is not None
        clock, control = self.plant.clock, self.control
        while True:
            await clock.sleep(self.settings.tick)
            if not self.plant.role.is_active():
                continue  # a standby of a redundant pair sends no orders: its active does (docs/redundancy.md)
            control.tick(clock.now(), liveness=not self._inbox)
            await self.flush()

    def _receive(self, topic: str, payload: bytes, retained: bool) -> None:
        """From the connection: queued with the time it came (liveness counts from then), read in turns (`_read`)."""
        assert self.plant is not None
        self._inbox.append((topic, payload, self.plant.clock.now()))
        self._mail.set()

    async def _read(self) -> None:
        """The vehicles' messages, a few at a time between scan cycles (a burst of states must not delay a 10 ms task)."""
        assert self.plant is not None
        clock, inbox = self.plant.clock, self._inbox
        while True:
            await self._mail.wait()
            self._mail.clear()
            while inbox:
                await clock.sleep(0)  # on the real clock: a scan cycle due within its guard runs first
                began = time.perf_counter()
                while inbox and time.perf_counter() - began < TURN_SECONDS:
                    topic, payload, received = inbox.popleft()
                    try:
                        self._on_message(topic, payload, received)
                    except Exception:  # one message the master chokes on must not end its reading
                        self.bad_messages += 1
                        log.exception("vda5050: a message on %s could not be handled", topic)

    async def flush(self) -> None:
        """Publish what the control decided, each message checked against its closed schema first."""
        assert self.plant is not None and self.control is not None and self.connection is not None
        outbox, self.control.outbox = self.control.outbox, []
        for index, (link, name, body) in enumerate(outbox):
            if index % TURN == TURN - 1:
                await self.plant.clock.sleep(0)  # a burst of orders in turns, scan cycles first
            if not self.plant.role.is_active():
                return  # fenced since the tick (a freeze in between): the new active orders
            message = {**link.headers.next(name, self.plant.clock.wall()), **body}
            found = problems("order" if name == topics.ORDER else "instantActions", self.settings.version, message)
            if found:
                self.schema_violations += 1
                log.error("vda5050: not sending an invalid %s to %s: %s", name, link.id, "; ".join(found[:3]))
                continue
            if name == topics.INSTANT_ACTIONS and link.identity.instant_actions_key != "actions":
                message[link.identity.instant_actions_key] = message.pop("actions")  # vda-5050-lib's 2.0 draft key
            topic = topics.topic(self.settings.interface, self.settings.version, link.identity.manufacturer,
                                 link.identity.serial_number, name)
            try:
                await self.connection.publish(topic, json.dumps(message, separators=(",", ":")))
                self.sent += 1
            except NotConnected:
                pass  # the broker is away: the resend after the reconnect carries it

    # -- what comes from the wire --------------------------------------------------------------------------------------

    def _on_broker(self, up: bool) -> None:
        assert self.plant is not None and self.control is not None
        self.plant.tags.submit([(BROKER_TAG, up)], Origin("vda5050", role=None))
        self.control.broker(up)
        if up:
            log.info("vda5050: connected to %s; subscribed to the vehicles' state, connection and factsheet", self.mqtt.url)

    def _on_message(self, topic: str, payload: bytes, received: float) -> None:
        assert self.plant is not None and self.control is not None
        address = topics.parse(topic, self.settings.interface, self.settings.version)
        if address is None:
            return
        link = self._by_topic.get((address.manufacturer, address.serial_number))
        if link is None:
            self._wire_log.warning(f"{address.manufacturer}/{address.serial_number}", "messages of unknown vehicles",
                                   "VDA 5050: a %s message of %s/%s, which is no driver: vda5050 robot of %s: ignored",
                                   address.name, address.manufacturer, address.serial_number, self.robots.path)
            return
        if address.name not in (topics.STATE, topics.CONNECTION, topics.FACTSHEET):
            return
        if len(payload) > MAX_MESSAGE:
            self._bad(link, address.name, f"{len(payload)} bytes, more than the {MAX_MESSAGE} a VDA 5050 message may have here")
            return
        try:
            message = decode(payload, address.name, self.settings.version, closed=False)
        except MessageError as error:
            if address.name != topics.FACTSHEET or not isinstance(document := _object(payload), dict):
                self._bad(link, address.name, str(error))
                return
            # A factsheet off the tables is still worth its figures (vda-5050-lib's own schema differs from 2.0's table).
            self._wire_log.warning(link.id, "factsheets off the tables", "VDA 5050 vehicle %s: its factsheet deviates from the "
                                   "%s tables (%s); its usable figures are taken", link.id, self.settings.version, error)
            message = {"manufacturer": link.identity.manufacturer, "serialNumber": link.identity.serial_number, **document}
        if (message["manufacturer"], message["serialNumber"]) != (link.identity.manufacturer, link.identity.serial_number):
            self._bad(link, address.name, f"the message on {link.id}'s topic says it is from {message['manufacturer']}/"
                                          f"{message['serialNumber']}")
            return
        now = received
        if address.name == topics.STATE:
            state = VehicleState.from_message(message)
            if state.position is not None and state.map_id and state.map_id != self.roadmap.map_id:
                self._bad(link, "state", f"its position is on map {state.map_id!r}, the roadmap's is {self.roadmap.map_id!r}")
                return
            link.note = ""
            self.control.on_state(link, state, now)
        elif address.name == topics.CONNECTION:
            self.control.on_connection(link, message["connectionState"])
        else:
            self._factsheet(link, message)

    def _bad(self, link: VehicleLink, kind: str, why: str) -> None:
        self.bad_messages += 1
        link.bad_messages += 1
        self._wire_log.warning(link.id, f"bad {kind} messages", "VDA 5050 vehicle %s: a bad %s message dropped: %s", link.id, kind, why,
                               detail=why[:80])
        link.note = f"master: bad {kind} message dropped: {why}"[:500]
        link.write(_error=link.error_text(link.state))

    def _factsheet(self, link: VehicleLink, message: dict[str, Any]) -> None:
        """A factsheet: the vehicle's own figures for the compatibility of case II; robots.yaml's win, differences said."""
        summary = FactsheetSummary.from_message(message)
        link.factsheet = summary
        spec = link.spec
        differences = []
        for ours, theirs in FACTSHEET_FIELDS:
            value = getattr(summary, ours if ours != "load_capacity" else "max_load_mass")
            declared = getattr(spec, ours)
            if value is not None and abs(value - declared) > 1e-6 * max(1.0, abs(declared)):
                differences.append(f"{ours}: robots.yaml {declared:g}, factsheet {theirs} {value:g}")
        if differences != self.factsheet_differences.get(link.id):
            self.factsheet_differences[link.id] = differences
            if differences:
                log.warning("vehicle %s: its factsheet differs from robots.yaml, which wins: %s", link.id, "; ".join(differences))


def _object(payload: bytes) -> Any:
    """The JSON value of a payload, None when it is not JSON."""
    try:
        return parse_json(payload)
    except MessageError:
        return None
