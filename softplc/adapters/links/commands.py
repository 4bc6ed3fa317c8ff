"""What the links offer the rest of the runtime and its clients: `links.list`, `links.tags` and `links.write`.

    links.list             anyone    every link: protocol, address, state, error, counts, its `_sys.links.` prefix
    links.tags [link]      anyone    every bound tag: link, source, direction, quality and why it is not good
    links.write tag value  operator  send a value to the remote a tag is bound out to, now; the remote's answer
                                     is the result (or the refusal), audited like every command

A client's write of a tag bound `out` or `both` (over OPC UA, Modbus, the HMI...) is audited as
an ordinary write when the plant takes it; the link then sends it as `links.write` in the
client's name, so the audit trail also holds the remote's answer — accepted, or refused with
the remote's reason (e.g. BadOutOfRange, exception 03) — with who asked and from where.
The HMI's Tasks page shows the links from `links.list` and the `_sys.links.` tags; nothing
imports this adapter.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from softplc.adapters.links.link import WRITE_COMMAND, LinkError
from softplc.core.commands import CommandRefused, Permission
from softplc.core.tagdb import Origin, WriteRejected
from softplc.core.tags import Quality
from softplc.util.suggest import did_you_mean

if TYPE_CHECKING:
    from softplc.adapters.links.link import Link
    from softplc.core.plant import Plant


def register_commands(plant: Plant, links: Mapping[str, Link], writers: Mapping[str, Link]) -> list[Callable[[], None]]:
    """Register the links' commands; `writers` maps each tag bound out (or both) to its link. Returns the undos."""
    commands = plant.commands

    def listing(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        return [link.describe() for link in links.values()]

    def tags(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        wanted = arguments.get("link")
        if wanted is not None and wanted not in links:
            raise CommandRefused(f"no link {wanted!r}{did_you_mean(str(wanted), links)}")
        rows = []
        for link in links.values():
            if wanted is not None and link.name != wanted:
                continue
            health = link.health()
            for bound in link.bound.values():
                binding = bound.binding
                tag = plant.tags[bound.name]
                reason = ""
                if binding.direction.reads:
                    reason = bound.reason if bound.quality is not Quality.GOOD else ""
                    if not reason and health is not Quality.GOOD:
                        reason = f"link {link.name} is {link.state.value}: {link.error}"
                if not reason and bound.refused:
                    reason = bound.refused
                rows.append({"tag": bound.name, "link": link.name, "source": binding.source, "direction": binding.direction.value,
                             "quality": tag.quality.value, "reason": reason})
        return rows

    async def write(arguments: Mapping[str, Any], origin: Origin) -> str:
        name = str(arguments.get("tag", ""))
        link = writers.get(name)
        if link is None:
            bound_in = any(name in candidate.bound for candidate in links.values())
            why = "is bound in only: its value comes from the remote" if bound_in else "is not bound out to a link"
            raise CommandRefused(f"{name} {why}{'' if bound_in else did_you_mean(name, writers)}")
        if "value" not in arguments:
            raise CommandRefused("links.write needs a value")
        try:
            value = plant.tags.validate(name, arguments["value"], role=origin.role)
        except WriteRejected as rejected:
            raise CommandRefused(str(rejected)) from None
        bound = link.bound[name]
        try:
            refusal = await link.write_one(bound, value)
        except LinkError as error:
            raise CommandRefused(f"{name} = {value!r} not sent to {link.name}: {error}") from None
        if refusal is not None:
            raise CommandRefused(f"{link.name} ({link.settings.address}) refused {name} = {value!r}: {refusal}")
        if plant.tags.value(name) != value:
            plant.tags.submit([(name, value)], link.origin)  # the tag follows what the remote took
        return f"{name} = {value!r} taken by {link.name} ({link.settings.address})"

    return [
        commands.register("links.list", listing, permission=Permission.VIEW, description="list the links to other controllers"),
        commands.register("links.tags", tags, permission=Permission.VIEW, description="list the tags bound to other controllers",
                          arguments={"link": "only this link's tags (optional)"}),
        commands.register(WRITE_COMMAND, write, permission=Permission.ACKNOWLEDGE,
                          description="send a bound tag's value to its remote controller",
                          arguments={"tag": "a tag bound out (or both) to a link", "value": "the value"}),
    ]
