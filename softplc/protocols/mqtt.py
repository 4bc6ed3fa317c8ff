"""One MQTT connection that stays up: reconnects with backoff, re-subscribes, and says when it is up or down.

    connection = MqttConnection(settings, "vda5050", clock, will=lambda: Will("…/connection", b"…", qos=1, retain=True))
    connection.subscribe("uagv/v2/+/+/state", handle)      # handle(topic, payload, retained), called on the loop
    connection.on_state(lambda up: ...)                     # True after each (re)connect, False when it drops
    task = asyncio.create_task(connection.run())            # until cancelled; then await connection.close()
    await connection.publish("uagv/v2/acme/001/order", payload, qos=0)

The client is aiomqtt (paho underneath), which does not reconnect by itself: `run()` enters it
again with a growing delay (1 s doubling to `max_backoff`, on the plant's clock), subscribes to
every filter again, and calls `on_state(True)` so its user can publish what a new session needs
(a retained ONLINE, a Sparkplug birth). The last will is asked for at each connect (`will()`),
so it can carry what changes per session (Sparkplug's bdSeq). An incoming payload larger than
`max_payload` is dropped with one log line per topic and minute, never handed on.

`restart(reason)` ends the session with a clean DISCONNECT (the broker drops the last will) and
connects again at once, without the backoff: what a Sparkplug edge node must do when its
primary host goes offline (it publishes its NDEATH itself first).
"""

from __future__ import annotations

import asyncio
import logging
import ssl
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from softplc.protocols.mqtt_settings import MqttSettings
from softplc.util.peers import PeerLog

log = logging.getLogger(__name__)

MAX_PAYLOAD = 1024 * 1024  # bytes: a bigger message is dropped (a vehicle's state is a few kB)
MAX_BACKOFF = 30.0  # seconds between reconnect attempts, at most

Handler = Callable[[str, bytes, bool], None]


class _Clock(Protocol):
    async def sleep(self, seconds: float) -> None: ...


@dataclass(frozen=True)
class Will:
    """The last will the broker publishes when this connection dies without saying goodbye."""

    topic: str
    payload: bytes
    qos: int = 0
    retain: bool = False


class NotConnected(ConnectionError):
    """A publish while the broker is unreachable."""


class MqttConnection:
    """See the module docstring."""

    def __init__(self, settings: MqttSettings, user: str, clock: _Clock, *, will: Callable[[], Will | None] | None = None,
                 clean_start: bool = True, max_payload: int = MAX_PAYLOAD, max_backoff: float = MAX_BACKOFF) -> None:
        self.settings = settings
        self.client_id = f"{settings.client_id}-{user}"
        self.clock = clock
        self.will = will
        self.clean_start = clean_start
        self.max_payload = max_payload
        self.max_backoff = max_backoff
        self.connected = False
        self.connects = 0  # sessions opened so far
        self.last_error = ""
        self.received = 0
        self.dropped = 0  # payloads over max_payload, or raising handlers
        self._client: Any = None
        self._subscriptions: dict[str, tuple[int, Handler]] = {}
        self._state_listeners: list[Callable[[bool], None]] = []
        self._peer_log = PeerLog(log, service="MQTT")
        self._closing = False
        self._restarting = ""  # why the current session is being ended on purpose

    # -- what users call ---------------------------------------------------------------------

    def subscribe(self, topic_filter: str, handler: Handler, qos: int = 0) -> None:
        """Receive the messages of `topic_filter` now (when connected) and after every reconnect."""
        self._subscriptions[topic_filter] = (qos, handler)
        if self._client is not None and self.connected:
            asyncio.ensure_future(self._subscribe_one(topic_filter, qos))

    def on_state(self, listener: Callable[[bool], None]) -> Callable[[], None]:
        """Call `listener(True)` after each connect and `listener(False)` when the connection drops."""
        self._state_listeners.append(listener)
        return lambda: self._state_listeners.remove(listener)

    async def publish(self, topic: str, payload: bytes | str, qos: int = 0, retain: bool = False) -> None:
        """Send one message; NotConnected while the broker is unreachable (nothing is queued here)."""
        client = self._client
        if client is None or not self.connected:
            raise NotConnected(f"not connected to the MQTT broker at {self.settings.url}")
        from aiomqtt import MqttError

        try:
            await client.publish(topic, payload, qos=qos, retain=retain)
        except MqttError as error:
            raise NotConnected(f"MQTT publish to {topic} failed: {error}") from None

    async def run(self) -> None:
        """Connect, and connect again whenever the connection drops, until cancelled."""
        from aiomqtt import MqttError

        delay = 1.0
        while not self._closing:
            began = time.monotonic()
            try:
                await self._session()
            except MqttError as error:
                self.last_error = str(error)
            except OSError as error:  # name resolution, TLS files
                self.last_error = str(error)
            finally:
                self._client = None
                self._set_state(False)
            if self._closing:
                return
            if self._restarting:
                log.info("MQTT %s: reconnecting (%s)", self.client_id, self._restarting)
                self._restarting = ""
                delay = 1.0
                continue
            if time.monotonic() - began > 2 * delay:
                delay = 1.0  # it was up for a while: the next outage starts from a short wait again
            self._peer_log.warning(self.settings.url, "lost connections", "MQTT %s: broker %s unreachable (%s); retrying in %g s",
                                   self.client_id, self.settings.url, self.last_error or "closed", delay)
            await self.clock.sleep(delay)
            delay = min(delay * 2, self.max_backoff)

    async def restart(self, reason: str) -> None:
        """End the current session cleanly (no last will) and connect again at once; nothing while disconnected."""
        client = self._client
        if client is None or self._closing:
            return
        self._restarting = reason
        try:
            await client.__aexit__(None, None, None)
        except Exception:  # already gone: run() reconnects all the same
            pass

    async def close(self) -> None:
        """Disconnect cleanly (the broker publishes no last will); `run()` then returns."""
        self._closing = True
        client = self._client
        if client is not None:
            try:
                await client.__aexit__(None, None, None)
            except Exception:  # already closing or gone: nothing to say goodbye to
                pass

    # -- inside --------------------------------------------------------------------------------

    async def _session(self) -> None:
        import aiomqtt

        settings = self.settings
        will = self.will() if self.will is not None else None
        protocol = aiomqtt.ProtocolVersion.V5 if settings.protocol == "5" else aiomqtt.ProtocolVersion.V311
        client = aiomqtt.Client(
            settings.host, settings.port, identifier=self.client_id, username=settings.username, password=settings.password(),
            protocol=protocol, keepalive=max(1, round(settings.keepalive)), tls_context=self._tls_context(),
            will=aiomqtt.Will(will.topic, will.payload, will.qos, will.retain) if will is not None else None,
            clean_session=self.clean_start if protocol == aiomqtt.ProtocolVersion.V311 else None,
            # paho's MQTT_CLEAN_START_FIRST_ONLY (3) is its default, and the only value it accepts outside MQTT 5.
            clean_start=True if self.clean_start and protocol == aiomqtt.ProtocolVersion.V5 else 3,
            timeout=10.0,
        )
        async with client:
            self._client = client
            self.connects += 1
            self.last_error = ""
            for topic_filter, (qos, _) in list(self._subscriptions.items()):
                await client.subscribe(topic_filter, qos=qos)
            log.info("MQTT %s: connected to %s", self.client_id, settings.url)
            self._set_state(True)
            async for message in client.messages:
                self._deliver(message)

    async def _subscribe_one(self, topic_filter: str, qos: int) -> None:
        try:
            if self._client is not None:
                await self._client.subscribe(topic_filter, qos=qos)
        except Exception as error:  # the connection dropped meanwhile: the next session subscribes
            log.debug("MQTT %s: subscribe %s failed: %s", self.client_id, topic_filter, error)

    def _deliver(self, message: Any) -> None:
        topic = message.topic.value
        payload = message.payload if isinstance(message.payload, bytes) else str(message.payload or "").encode()
        self.received += 1
        if len(payload) > self.max_payload:
            self.dropped += 1
            self._peer_log.warning(topic, "oversized messages", "MQTT %s: a %d-byte message on %s dropped (more than %d bytes)",
                                   self.client_id, len(payload), topic, self.max_payload)
            return
        for topic_filter, (_, handler) in self._subscriptions.items():
            if message.topic.matches(topic_filter):
                try:
                    handler(topic, payload, bool(message.retain))
                except Exception as error:  # one message a handler chokes on must not end the session
                    self.dropped += 1
                    self._peer_log.warning(topic, "failing messages", "MQTT %s: the handler of %s failed on a message: %s: %s",
                                           self.client_id, topic, type(error).__name__, error)

    def _set_state(self, up: bool) -> None:
        if self.connected == up:
            return
        self.connected = up
        for listener in list(self._state_listeners):
            try:
                listener(up)
            except Exception:
                log.exception("MQTT %s: a connection listener failed", self.client_id)

    def _tls_context(self) -> ssl.SSLContext | None:
        tls = self.settings.tls
        if tls is None:
            return None
        context = ssl.create_default_context(cafile=str(tls.ca_file) if tls.ca_file else None)
        if tls.cert_file is not None and tls.key_file is not None:
            context.load_cert_chain(str(tls.cert_file), str(tls.key_file))
        if not tls.verify:
            context.check_hostname = False
            context.verify_mode = ssl.CERT_NONE
        return context
