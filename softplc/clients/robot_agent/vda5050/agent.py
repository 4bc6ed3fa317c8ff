"""Our simulated TurtleBot as a VDA 5050 vehicle: any master control drives it over MQTT.

    softplc robot-agent --vda5050 mqtt://127.0.0.1:1883 --robot r04        # r04: driver: vda5050 in robots.yaml

The agent connects to the broker with a last will (`connection` CONNECTIONBROKEN, retained,
QoS 1), says ONLINE (retained) and publishes its factsheet (retained) at every connect,
subscribes to its `order` and `instantActions`, and drives the robot's simulated driver
(softplc.robotics.driver: A* on the map, pure pursuit) from node to released node
(softplc.clients.robot_agent.vda5050.vehicle). It publishes its state on every event and at
least every `state_interval` seconds (the spec's 30 s by default). When the broker goes away
the robot finishes its base and stops; the connection comes back on its own.
"""

from __future__ import annotations

import asyncio
import json
import logging
from typing import Any

from softplc.clients.robot_agent.vda5050.factsheet import factsheet_of
from softplc.clients.robot_agent.vda5050.vehicle import Vehicle
from softplc.core.clock import Clock, RealClock
from softplc.protocols.mqtt import MqttConnection, NotConnected, Will
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.protocols.vda5050 import topics
from softplc.protocols.vda5050.messages import Headers
from softplc.robotics.controller import SpeedLimits
from softplc.robotics.driver import Command, DriverSettings, Report, RobotDriver
from softplc.robotics.floor import Floor
from softplc.robotics.loop import ControlLoop
from softplc.robotics.peers import PeerView
from softplc.robotics.robots import Pose, RobotSpec

log = logging.getLogger(__name__)

STATE_INTERVAL = 30.0  # s: the state goes out at least this often (spec §6.10)


class VehicleIO:
    """The driver's goal from the vehicle's order; each cycle's pose back into the vehicle, and its state out."""

    def __init__(self, agent: VehicleAgent) -> None:
        self.agent = agent
        self._hold: tuple[float, float] | None = None

    def command(self) -> Command:
        driver, vehicle = self.agent.driver, self.agent.vehicle
        target = vehicle.target(driver.pose)
        if target is not None:
            self._hold = None
            # A new goal starts the driver by itself; status true would make it start again at every cycle
            # once it is within 0.5 m (its arrival), and so stop short of a node it must pass within its deviation.
            return Command(target[0], target[1], False)
        if self._hold is None:  # stand where it is (a decision point, paused, an action, cancelled)
            self._hold = (driver.pose.x, driver.pose.y)
        return Command(self._hold[0], self._hold[1], False)

    def peers(self) -> PeerView:
        return PeerView([], [])  # traffic between vehicles is the master control's (node and edge reservations)

    async def publish(self, report: Report) -> None:
        self.agent.after_cycle(report)


class VehicleAgent:
    """One robot as a VDA 5050 vehicle (see the module docstring)."""

    def __init__(self, spec: RobotSpec, floor: Floor, settings: MqttSettings, *, interface: str = topics.DEFAULT_INTERFACE,
                 version: str = topics.DEFAULT_VERSION, manufacturer: str | None = None, serial_number: str | None = None,
                 map_id: str = "factory", cycle: float = 0.1, limits: SpeedLimits | None = None, clock: Clock | None = None,
                 state_interval: float = STATE_INTERVAL, pose: Pose | None = None) -> None:
        identity = spec.vehicle
        self.spec = spec
        self.manufacturer = manufacturer or (identity.manufacturer if identity else "softplc")
        self.serial_number = serial_number or (identity.serial_number if identity else spec.id)
        self.interface, self.version = interface, version
        self.clock = clock or RealClock()
        self.cycle = cycle
        self.state_interval = state_interval
        speed = limits or SpeedLimits(spec.max_linear_speed, spec.max_angular_speed)
        self.driver = RobotDriver(spec, floor, speed, DriverSettings(), cycle=cycle, pose=pose or spec.start)
        self.vehicle = Vehicle(version, load_capacity=max(1, int(spec.load_capacity)))
        self.vehicle.map_id = map_id
        self.vehicle.pose = self.driver.pose
        self.headers = Headers(version, self.manufacturer, self.serial_number)
        self.connection = MqttConnection(settings, f"vehicle-{self.serial_number}", self.clock, will=self._will)
        self.connection.subscribe(self._topic(topics.ORDER), self._on_order)
        self.connection.subscribe(self._topic(topics.INSTANT_ACTIONS), self._on_instant_actions)
        self.connection.on_state(self._on_connection)
        self.states_sent = 0
        self._last_state = -1e9
        self._report: Report | None = None
        self._publishing: asyncio.Task[Any] | None = None

    async def run(self) -> None:
        """Connect and drive until cancelled; then say OFFLINE and disconnect."""
        loop = ControlLoop(self.driver, VehicleIO(self), self.clock, self.cycle)
        connection = asyncio.ensure_future(self.connection.run())
        driving = asyncio.ensure_future(loop.run())
        try:
            await asyncio.wait({connection, driving}, return_when=asyncio.FIRST_COMPLETED)
            for task in (connection, driving):
                if task.done():
                    task.result()  # a crash of either ends the agent with its error
        finally:
            driving.cancel()
            await self.stop()  # while the connection still runs: OFFLINE reaches the broker
            connection.cancel()
            await asyncio.gather(connection, driving, return_exceptions=True)

    async def stop(self) -> None:
        """Say OFFLINE (retained) and disconnect cleanly: the broker publishes no last will."""
        if self.connection.connected:
            try:
                await self._publish(topics.CONNECTION, {"connectionState": "OFFLINE"}, qos=1, retain=True)
            except NotConnected:
                pass
        await self.connection.close()

    # -- inside ---------------------------------------------------------------------------------------

    def _topic(self, name: str) -> str:
        return topics.topic(self.interface, self.version, self.manufacturer, self.serial_number, name)

    def _will(self) -> Will:
        message = {**self.headers.next(topics.CONNECTION, self.clock.wall()), "connectionState": "CONNECTIONBROKEN"}
        return Will(self._topic(topics.CONNECTION), json.dumps(message).encode(), qos=1, retain=True)

    def _on_connection(self, up: bool) -> None:
        if up:
            asyncio.ensure_future(self._announce())

    async def _announce(self) -> None:
        try:
            await self._publish(topics.CONNECTION, {"connectionState": "ONLINE"}, qos=1, retain=True)
            await self._publish(topics.FACTSHEET, factsheet_of(self.spec, self.version, self.state_interval), retain=True)
            await self._publish_state()
        except NotConnected:
            pass  # gone again: the next connect announces

    def _on_order(self, topic: str, payload: bytes, retained: bool) -> None:
        self.vehicle.on_order(payload)
        self._publish_soon()

    def _on_instant_actions(self, topic: str, payload: bytes, retained: bool) -> None:
        self.vehicle.on_instant_actions(payload)
        self._apply_pose()
        self._publish_soon()

    def _apply_pose(self) -> None:
        new_pose = self.vehicle.new_pose
        if new_pose is not None:  # initPosition: the simulated robot is put there
            self.vehicle.new_pose = None
            self.driver.pose = new_pose
            self.driver.goal = None
            self.driver.path = None

    def after_cycle(self, report: Report) -> None:
        self._report = report
        self.vehicle.pose = self.driver.pose
        self.vehicle.step(self.clock.now(), self.driver.pose, bool(report.speed or report.turn_rate))
        if self.vehicle.changed or self.clock.now() - self._last_state >= self.state_interval:
            self._publish_soon()

    def _publish_soon(self) -> None:
        """Publish the state now (one publish in flight at a time; a change meanwhile is sent after it)."""
        if self._publishing is None or self._publishing.done():
            self._publishing = asyncio.ensure_future(self._publish_state())

    async def _publish_state(self) -> None:
        if self.vehicle.factsheet_requested:
            self.vehicle.factsheet_requested = False
            await self._send(topics.FACTSHEET, factsheet_of(self.spec, self.version, self.state_interval), retain=True)
        report = self._report
        self.vehicle.changed = False
        self._last_state = self.clock.now()
        body = self.vehicle.state(self.driver.pose, report.speed if report else 0.0, report.turn_rate if report else 0.0)
        if await self._send(topics.STATE, body):
            self.states_sent += 1

    async def _send(self, name: str, body: dict[str, Any], *, qos: int = 0, retain: bool = False) -> bool:
        try:
            await self._publish(name, body, qos=qos, retain=retain)
            return True
        except NotConnected:
            return False  # the broker is away: the state after the reconnect tells the master everything

    async def _publish(self, name: str, body: dict[str, Any], *, qos: int = 0, retain: bool = False) -> None:
        message = {**self.headers.next(name, self.clock.wall()), **body}
        await self.connection.publish(self._topic(name), json.dumps(message, separators=(",", ":")), qos=qos, retain=retain)
