"""Commands: the actions a person takes on a running plant, through one door with an origin.

Tag writes go through `TagDatabase.submit`; everything else an operator or engineer does —
acknowledge or shelve an alarm, force a tag, stop or restart a program, apply an online change —
is a named command registered here by the module that owns it (the alarm engine, the runtime...)
and called by any adapter (OPC UA methods, the HMI's API, the CLI) with the caller's `Origin`:

    runtime.commands.register("alarms.acknowledge", handler, permission=Permission.ACKNOWLEDGE,
                              description="acknowledge alarms", arguments={"alarm": "alarm name"})
    result = await runtime.commands.call("alarms.acknowledge", {"alarm": "t01_full"}, origin)

One place checks the role (`Permission`), so every path refuses a viewer the same way, and one
place reports each call, carried out or refused, to listeners (`on_call`) — where the audit trail
listens. A handler refuses with `CommandRefused("why")`; it may be a plain function or a coroutine
function (e.g. one that waits for the next scan boundary).
"""

from __future__ import annotations

import enum
import inspect
import logging
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from softplc.core.roles import Role
from softplc.core.tagdb import Origin, origin_of

log = logging.getLogger(__name__)


class Permission(enum.Enum):
    """What a command needs of the caller's role (`softplc.core.roles`)."""

    VIEW = "view"  # any role: reading state (lists, details)
    ACKNOWLEDGE = "acknowledge"  # operator and engineer: alarm actions, resets
    ENGINEER = "engineer"  # engineer only: forcing, program control, online change

    def allows(self, role: Role | None) -> bool:
        if role is None:  # code inside the runtime
            return True
        if self is Permission.VIEW:
            return True
        if self is Permission.ACKNOWLEDGE:
            return role.may_acknowledge
        return role.may_engineer


class CommandRefused(Exception):
    """A command that was not carried out; the message says why, for the person who asked."""


class UnknownCommand(CommandRefused):
    """No command of that name is registered."""


Handler = Callable[[Mapping[str, Any], Origin], Any | Awaitable[Any]]


@dataclass(frozen=True)
class Command:
    """A registered command: its handler, who may call it, and what it takes."""

    name: str
    handler: Handler
    permission: Permission
    description: str = ""
    arguments: Mapping[str, str] = field(default_factory=dict)  # name → description
    audited: bool = True  # False for commands that only read (lists, details)
    on_standby: bool = False  # an action a standby of a redundant pair carries out too (its own, e.g. a switchover)


@dataclass(frozen=True)
class CommandCall:
    """One call of a command, as `on_call` listeners see it."""

    time: float  # wall-clock seconds of the runtime clock
    origin: Origin
    command: str
    arguments: Mapping[str, Any]
    accepted: bool
    detail: str = ""  # why it was refused, or what it did


CallListener = Callable[[CommandCall], None]


class Commands:
    """The registry of commands, and the one door through which they are called."""

    def __init__(self, now: Callable[[], float]) -> None:
        self._now = now
        self._commands: dict[str, Command] = {}
        self._listeners: list[CallListener] = []
        # Why actions are refused here ('' when they are not): a standby's or fenced plant's
        # refusal naming the active (softplc/core/plant_role.py); queries (VIEW) always run.
        self.refusal: Callable[[], str] | None = None

    def register(
        self,
        name: str,
        handler: Handler,
        *,
        permission: Permission,
        description: str = "",
        arguments: Mapping[str, str] | None = None,
        audited: bool | None = None,
        on_standby: bool = False,
    ) -> Callable[[], None]:
        """Register a command; returns an unregister. Names are dotted: `alarms.acknowledge`."""
        if name in self._commands:
            raise ValueError(f"command {name!r} is registered twice")
        self._commands[name] = Command(
            name, handler, permission, description, dict(arguments or {}),
            audited=permission is not Permission.VIEW if audited is None else audited, on_standby=on_standby,
        )
        return lambda: self._commands.pop(name, None)

    def __contains__(self, name: object) -> bool:
        return name in self._commands

    def get(self, name: str) -> Command | None:
        return self._commands.get(name)

    def names(self, prefix: str = "") -> list[str]:
        return sorted(name for name in self._commands if name.startswith(prefix))

    def on_call(self, listener: CallListener) -> Callable[[], None]:
        """Call `listener(call)` after every call of an audited command, carried out or refused."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener)

    async def call(self, name: str, arguments: Mapping[str, Any] | None, origin: Origin | str) -> Any:
        """Check the caller's role, run the command, report the call; raise CommandRefused if refused."""
        origin = origin_of(origin)
        arguments = dict(arguments or {})
        command = self._commands.get(name)
        if command is None:
            refusal: CommandRefused = UnknownCommand(f"no such command {name!r}")
            self._report(origin, name, arguments, refusal, audited=origin.role is not None)
            raise refusal
        if not command.permission.allows(origin.role):
            role = origin.role.value if origin.role is not None else "internal"
            refusal = CommandRefused(f"role {role} may not {command.description or name}")
            self._report(origin, name, arguments, refusal, audited=command.audited)
            raise refusal
        if command.permission is not Permission.VIEW and not command.on_standby and self.refusal is not None:
            reason = self.refusal()
            if reason:
                refusal = CommandRefused(reason)
                self._report(origin, name, arguments, refusal, audited=command.audited)
                raise refusal
        unknown = [key for key in arguments if command.arguments and key not in command.arguments]
        if unknown:
            refusal = CommandRefused(f"{name}: unknown argument {unknown[0]!r}; it takes: {', '.join(command.arguments) or 'none'}")
            self._report(origin, name, arguments, refusal, audited=command.audited)
            raise refusal
        try:
            result = command.handler(arguments, origin)
            if inspect.isawaitable(result):
                result = await result
        except CommandRefused as refused:
            self._report(origin, name, arguments, refused, audited=command.audited)
            raise
        self._report(origin, name, arguments, None, audited=command.audited, done=result)
        return result

    def refused(self, name: str, arguments: Mapping[str, Any] | None, origin: Origin | str, reason: str) -> None:
        """Report a call an adapter refused before calling it (no login, no CSRF token), as `db.refused` does for writes."""
        command = self._commands.get(name)
        self._report(origin_of(origin), name, dict(arguments or {}), CommandRefused(reason),
                     audited=command.audited if command is not None else True)

    def _report(self, origin: Origin, name: str, arguments: dict[str, Any], refusal: CommandRefused | None,
                *, audited: bool, done: Any = None) -> None:
        if not audited or origin.role is None or not self._listeners:
            return
        # What it did: a text result, or the "summary" of a structured one (e.g. an online change's).
        summary = done.get("summary") if isinstance(done, Mapping) else done
        detail = str(refusal) if refusal is not None else (summary if isinstance(summary, str) else "")
        call = CommandCall(self._now(), origin, name, arguments, refusal is None, detail)
        for listener in list(self._listeners):
            try:
                listener(call)
            except Exception:  # a broken listener must never change the command's outcome
                log.exception("command listener %r failed", listener)
