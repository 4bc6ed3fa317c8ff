"""ServerRedundancy (OPC UA Part 4 §6.6.2, Part 5 §6.3.7) when the runtime is a member of a redundant pair.

asyncua serves ServiceLevel as a constant 255 and leaves Server/ServerRedundancy at
RedundancySupport None. When the plant has the `redundancy.servers` query (the redundancy
adapter registers it; this module never imports it), the server shows instead:

- RedundancySupport = Hot, and ServerUriArray = the application URIs of both members (each
  member serves under its own URI, `urn:softplc:PLANT:MEMBER`);
- ServiceLevel = the value of the `_sys.redundancy.service_level` tag, pushed the moment it
  changes: ≥ 200 on the active, < 200 on the standby, 1 while fenced — so a standard client
  (asyncua's HaClient, node-opcua) picks the active and fails over when it changes.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from asyncua import ua

from softplc.core.origin import Origin

if TYPE_CHECKING:
    from asyncua import Server

    from softplc.core.plant import Plant
    from softplc.core.tags import Tag

log = logging.getLogger(__name__)

QUERY = "redundancy.servers"
SERVICE_LEVEL = ua.NodeId(ua.ObjectIds.Server_ServiceLevel)
REDUNDANCY_SUPPORT = ua.NodeId(ua.ObjectIds.Server_ServerRedundancy_RedundancySupport)
SERVER_URI_ARRAY = ua.NodeId(ua.ObjectIds.Server_ServerRedundancy_ServerUriArray)
_ORIGIN = Origin("opcua", "redundancy", role=None)


async def redundancy_info(plant: Plant) -> dict[str, Any] | None:
    """The pair's redundancy as its adapter describes it; None for a runtime alone."""
    if QUERY not in plant.commands:
        return None
    info = await plant.commands.call(QUERY, {}, _ORIGIN)
    return info if isinstance(info, dict) else None


class ServerRedundancy:
    """Keeps the server's redundancy nodes true to the pair (see the module docstring)."""

    def __init__(self, server: Server, plant: Plant, tag: str) -> None:
        self.server = server
        self.plant = plant
        self.tag = tag
        self.level = -1
        self._undo: Callable[[], None] | None = None
        self._writes: list[asyncio.Future[Any]] = []

    @classmethod
    async def install(cls, server: Server, plant: Plant, info: dict[str, Any]) -> ServerRedundancy:
        support = getattr(ua.RedundancySupport, str(info.get("support", "Hot")))
        await server.write_attribute_value(REDUNDANCY_SUPPORT, ua.DataValue(ua.Variant(support, ua.VariantType.Int32)))
        uris = [str(uri) for uri in info.get("server_uris", [])]
        await server.write_attribute_value(SERVER_URI_ARRAY, ua.DataValue(ua.Variant(uris, ua.VariantType.String)))
        redundancy = cls(server, plant, str(info.get("service_level_tag", "_sys.redundancy.service_level")))
        level = int(plant.tags.value(redundancy.tag)) if redundancy.tag in plant.tags else 1
        redundancy.level = level
        await server.write_attribute_value(SERVICE_LEVEL, ua.DataValue(ua.Variant(level, ua.VariantType.Byte)))
        redundancy._undo = plant.tags.on_change(redundancy._changed)
        return redundancy

    def _changed(self, tags: Sequence[Tag]) -> None:
        for tag in tags:
            if tag.name == self.tag:
                self._push(int(tag.value))

    def _push(self, level: int) -> None:
        level = max(0, min(255, level))
        if level == self.level:
            return
        self.level = level
        value = ua.DataValue(ua.Variant(level, ua.VariantType.Byte))
        # The tag's change callback is not a coroutine: the write (which notifies the node's
        # monitored items) runs as soon as the loop turns, in the order the changes came.
        self._writes.append(asyncio.ensure_future(self.server.write_attribute_value(SERVICE_LEVEL, value)))
        self._writes = [write for write in self._writes if not write.done()]

    def stop(self) -> None:
        if self._undo is not None:
            self._undo()
            self._undo = None
