"""The links adapter: one `Link` per remote controller, started with the plant, and what it offers the rest.

At start every link tries its first connection (at once, in parallel, each within its timeout).
A remote that answers and says a binding is wrong (a node it does not have, another type, a
register it does not serve) stops the start with located errors, like `softplc check`; a remote
that does not answer does not: its tags are BAD and the link keeps reconnecting.

Local changes of `out` and `both` tags go to their link (one listener, `on_change`); a client's
write of such a tag (`on_write`) is sent through the `links.write` command with the client's
origin, so the remote's answer is audited with who asked (commands.py).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from softplc.adapters.links.settings import LinkSettings
from softplc.core.clock import wait_for
from softplc.core.plant import AdapterError, Plant
from softplc.core.tagdb import WriteEvent
from softplc.core.tags import Quality, Tag
from softplc.util.tasks import cancel_and_wait

if TYPE_CHECKING:
    from softplc.adapters.links.link import Link
    from softplc.config.plant import PlantConfig

log = logging.getLogger(__name__)


class LinksAdapter:
    """Every link of the plant (see the module docstring)."""

    name = "links"

    def __init__(self, config: PlantConfig, links: Sequence[LinkSettings]) -> None:
        self.config = config
        self.settings = list(links)
        self.links: dict[str, Link] = {}
        self.writers: dict[str, Link] = {}  # tag → the link it is sent out on
        self._tasks: list[asyncio.Task[Any]] = []
        self._undo: list[Any] = []
        self.plant: Plant | None = None

    async def start(self, plant: Plant) -> None:
        from softplc.adapters.links.commands import register_commands

        self.plant = plant
        for settings in self.settings:
            link = _make(settings, plant)
            self.links[settings.name] = link
            for bound in link.bound.values():
                if bound.binding.direction.writes:
                    self.writers[bound.name] = link
        for link in self.links.values():
            link.publisher.publish(link.readers, Quality.BAD)  # nothing read yet: BAD until the remote answers
            self._tasks.append(plant.spawn(link.run(), f"link-{link.name}"))
        longest = max((s.timeout * 3 + 1.0 for s in self.settings), default=1.0)
        try:
            await wait_for(plant.clock, asyncio.gather(*(link.first_attempt.wait() for link in self.links.values())), longest)
        except TimeoutError:
            pass  # a remote slower than that connects later, like one that is down
        problems = [self.config.problem((*binding.path, "source"), f"link {link.name}: {reason}")
                    for link in self.links.values() if link.connections for binding, reason in link.binding_problems()]
        if problems:
            await self.stop()
            raise AdapterError("the remote controllers refuse bindings:\n" + "\n".join(f"  {problem}" for problem in problems))
        self._undo = [plant.tags.on_change(self._changed), plant.tags.on_write(self._written), *register_commands(plant, self.links, self.writers)]

    async def stop(self) -> None:
        for undo in self._undo:
            undo()
        self._undo = []
        await cancel_and_wait(self._tasks)
        self._tasks = []
        for link in self.links.values():
            try:
                await link.close()
            except Exception as error:  # stopping: a connection that fails to close is gone anyway
                log.debug("link %s: %r while closing", link.name, error)

    def _changed(self, tags: Sequence[Tag]) -> None:
        writers = self.writers
        if not writers:
            return
        by_link: dict[Link, list[Tag]] = {}
        for tag in tags:
            link = writers.get(tag.name)
            if link is not None:
                by_link.setdefault(link, []).append(tag)
        for link, changed in by_link.items():
            link.local_changes(changed)

    def _written(self, events: Sequence[WriteEvent]) -> None:
        for event in events:
            link = self.writers.get(event.tag)
            if link is not None and event.accepted:
                link.client_writes[event.tag] = (event.new, event.origin)

    def describe(self) -> str:
        parts = [f"{link.name} ({link.settings.protocol} {link.settings.address}, {len(link.bound)} tags, {link.state.value})"
                 for link in self.links.values()]
        return "links: " + ", ".join(parts) if parts else "links: none"

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py)."""
        links = self.links.values()
        qualities: dict[tuple[str, str], int] = {}
        for link in links:
            for quality in Quality:
                qualities[(link.name, quality.value)] = 0
            for bound in link.readers:
                shown = bound.shown[1] if bound.shown is not None else Quality.BAD
                qualities[(link.name, shown.value)] += 1
        return {
            "connected": {(link.name,): int(link.connected) for link in links},
            "tags": qualities,
            "requests": {(link.name,): link.requests for link in links},
            "reconnects": {(link.name,): link.reconnects for link in links},
            "writes": {(link.name, result): count for link in links for result, count in link.writes.items()},
            "round_trip": {(link.name,): link.round_trip for link in links},
        }


def _make(settings: LinkSettings, plant: Plant) -> Link:
    if settings.protocol == "opcua":
        from softplc.adapters.links.opcua_link import OpcuaLink

        return OpcuaLink(settings, plant)
    from softplc.adapters.links.modbus_link import ModbusLink

    return ModbusLink(settings, plant)
