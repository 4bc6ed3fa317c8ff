"""The embedded MQTT broker (`mqtt: {embedded: true}`): amqtt inside the runtime, for a laptop demo with nothing installed.

It is NOT for production: no TLS, no users, no ACLs, MQTT 3.1.1 only, about 1.3k messages/s
(FIELD-NOTES). The section refuses it on anything but a loopback address. A plant on a network
uses a real broker (mosquitto with TLS and per-vehicle ACLs: docs/vda5050.md).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from softplc.protocols.mqtt_settings import MqttSettings

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)


class EmbeddedBroker:
    """amqtt's broker on the `mqtt:` url's loopback host and port, for as long as the runtime runs."""

    name = "mqtt-broker"

    def __init__(self, settings: MqttSettings) -> None:
        self.settings = settings
        self._broker: Any = None

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        for noisy in ("amqtt", "transitions"):
            logging.getLogger(noisy).setLevel(logging.WARNING)
        from amqtt.broker import Broker

        settings = self.settings
        broker = Broker({
            "listeners": {"default": {"type": "tcp", "bind": f"{settings.host}:{settings.port}"}},
            "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin": {"allow_anonymous": True}},
        })
        try:
            await broker.start()
        except Exception as error:  # amqtt wraps the bind error in its own
            raise AdapterError(f"mqtt: the embedded broker cannot listen on {settings.host}:{settings.port}: {error} "
                               "(another broker there? then drop 'embedded: true' and use it)") from None
        self._broker = broker
        log.warning("mqtt: embedded broker (amqtt) on %s: for a demo only, NOT for production (no TLS, no users, no ACLs)", settings.url)

    async def stop(self) -> None:
        if self._broker is not None:
            try:
                await self._broker.shutdown()
            except Exception as error:  # already gone: nothing to shut
                log.debug("mqtt: embedded broker shutdown: %s", error)
            self._broker = None

    def describe(self) -> str:
        return f"embedded MQTT broker (amqtt; a demo, NOT for production) on {self.settings.url}"
