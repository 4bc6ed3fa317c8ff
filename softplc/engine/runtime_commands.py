"""The commands the runtime itself offers (see `softplc/core/commands.py`): faults and forcing.

    runtime.reset_faults               operator, engineer   clear program faults and the ERROR state
    tags.force   {tag, value}          engineer             force a tag (softplc/core/forcing.py)
    tags.unforce {tag, restore}        engineer             release it (restore: back to its value before)
    tags.forces                        any role             the forces in effect

A value may be given typed (JSON from the HMI) or as text (`3.5`, `true`), parsed by the tag's type.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from softplc.core.commands import CommandRefused, Commands, Permission
from softplc.core.datatypes import TypeMismatch
from softplc.core.tagdb import Origin, TagDatabase, WriteRejected
from softplc.engine.scan import ProgramState, Task
from softplc.util.plurals import plural


class _Runtime(Protocol):
    """What these commands use of `softplc.app.runtime.Runtime` (which imports this module)."""

    commands: Commands
    db: TagDatabase
    tasks: Sequence[Task]

    def reset_faults(self) -> None: ...


def register_runtime_commands(runtime: _Runtime) -> None:
    commands, db = runtime.commands, runtime.db

    def reset_faults(arguments: Mapping[str, Any], origin: Origin) -> str:
        faulted = [i.name for t in runtime.tasks for i in t.programs if i.state is ProgramState.FAULTED]
        runtime.reset_faults()
        return f"reset {plural(len(faulted), 'faulted program')}" + (f": {', '.join(faulted)}" if faulted else "")

    def force(arguments: Mapping[str, Any], origin: Origin) -> str:
        name = _tag_argument(arguments)
        if "value" not in arguments:
            raise CommandRefused("tags.force needs a value")
        value = arguments["value"]
        tag = db.get(name)
        try:
            if isinstance(value, str) and tag is not None:
                value = tag.definition.type.parse(value)
            forced = db.force(name, value, origin)
        except TypeMismatch as error:
            raise CommandRefused(f"{name}: type mismatch: {error}") from None
        except WriteRejected as rejected:
            raise CommandRefused(str(rejected)) from None
        return f"{name} forced to {forced!r} from the next cycle"

    def unforce(arguments: Mapping[str, Any], origin: Origin) -> str:
        name = _tag_argument(arguments)
        restore = arguments.get("restore", False)
        if isinstance(restore, str):
            restore = restore.strip().lower() in ("true", "1", "yes", "on")
        if not db.unforce(name, restore=bool(restore)):
            raise CommandRefused(f"{name} is not forced")
        return f"{name} unforced{' and restored' if restore else ''} from the next cycle"

    def forces(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        return [
            {"tag": f.tag, "value": f.value, "since": f.since, "by": str(f.origin), "previous": f.previous}
            for f in db.forces.active()
        ]

    commands.register("runtime.reset_faults", reset_faults, permission=Permission.ACKNOWLEDGE,
                      description="reset program faults and the ERROR state")
    commands.register("tags.force", force, permission=Permission.ENGINEER, description="force tags",
                      arguments={"tag": "tag name", "value": "the forced value"})
    commands.register("tags.unforce", unforce, permission=Permission.ENGINEER, description="unforce tags",
                      arguments={"tag": "tag name", "restore": "true: back to the value before the force"})
    commands.register("tags.forces", forces, permission=Permission.VIEW, description="list forced tags")


def _tag_argument(arguments: Mapping[str, Any]) -> str:
    name = arguments.get("tag")
    if not isinstance(name, str) or not name:
        raise CommandRefused("give the tag's name as 'tag'")
    return name
