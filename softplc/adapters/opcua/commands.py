"""The OPC UA door to the runtime's commands: `Objects/Commands` with `Call` and `List`.

    Call(name: String, argumentsJSON: String) -> resultJSON: String
        resultJSON is {"ok": true, "result": ...} or {"ok": false, "error": "why it was refused"}.
        A caller whose role may not call the command gets BadUserAccessDenied (the registry still
        records the refusal); argumentsJSON that is not a JSON object gets BadInvalidArgument.
    List() -> commandsJSON: String
        [{"name", "permission", "description", "arguments": {name: description}}, ...]

The role is the session's (`softplc.adapters.opcua.roles`) and is checked by the command registry
(`softplc.core.commands`), exactly as for the HMI and the CLI; the Origin carries the session's user
and peer address. The command line's clients reach the runtime through here (softplc/clients/door_client.py).

asyncua hands a method only the object's NodeId and the arguments, not the calling session:
`install_caller_context` wraps each new session's Call so a method can ask `current_origin()`.
"""

from __future__ import annotations

import contextvars
import json
import logging
from typing import TYPE_CHECKING, Any

from asyncua import Server, ua
from asyncua.server.address_space import AttributeValue

from softplc.adapters.opcua.roles import role_of
from softplc.core.commands import CommandRefused, Commands
from softplc.core.tagdb import Origin
from softplc.protocols.opcua_names import COMMANDS_OBJECT

if TYPE_CHECKING:
    from asyncua.server.internal_server import InternalServer

log = logging.getLogger(__name__)

_caller: contextvars.ContextVar[tuple[Origin, ua.NodeId] | None] = contextvars.ContextVar("softplc_opcua_caller", default=None)


def install_caller_context(iserver: InternalServer) -> None:
    """Make every session created from now on publish its caller (`current_origin()`) while it calls methods."""
    if getattr(iserver, "_softplc_caller_context", False):
        return
    create_session = iserver.create_session

    def create_with_caller(*args: Any, **kwargs: Any) -> Any:
        session = create_session(*args, **kwargs)
        call = session.call

        async def call_as_caller(params: list[ua.CallMethodRequest]) -> list[ua.CallMethodResult]:
            user = session.user
            role = role_of(user)
            name = getattr(user, "name", None) or ("internal" if role is None else "anonymous")
            token = _caller.set((Origin("opcua", name, _peer(session.name), role), session.session_id))
            try:
                return await call(params)
            finally:
                _caller.reset(token)

        session.call = call_as_caller
        return session

    iserver.create_session = create_with_caller  # type: ignore[method-assign]
    iserver._softplc_caller_context = True  # type: ignore[attr-defined]


def _peer(name: Any) -> str:
    """'host:port' of a session's peer name (asyncua keeps the socket's ('host', port))."""
    if isinstance(name, (tuple, list)) and len(name) >= 2:
        return f"{name[0]}:{name[1]}"
    return str(name or "")


def current_origin() -> Origin | None:
    """The Origin of the client session whose method call is being served (None: no client call)."""
    caller = _caller.get()
    return caller[0] if caller is not None else None


def current_session_id() -> ua.NodeId | None:
    """The SessionId of the client session whose method call is being served."""
    caller = _caller.get()
    return caller[1] if caller is not None else None


def refused_by_role(commands: Commands, name: str, origin: Origin) -> bool:
    """Whether a refusal of command `name` for `origin` was about its role."""
    command = commands.get(name)
    return command is not None and not command.permission.allows(origin.role)


async def call_command(commands: Commands, name: str, arguments: dict[str, Any], origin: Origin) -> tuple[ua.StatusCode | None, Any, CommandRefused | None]:
    """Call a command for an OPC UA client: (BadUserAccessDenied if its role may not, result, the refusal)."""
    try:
        return None, await commands.call(name, arguments, origin), None
    except CommandRefused as refused:
        if refused_by_role(commands, name, origin):
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied), None, refused
        return None, None, refused


class CommandsDoor:
    """`Objects/Commands` (see the module docstring)."""

    def __init__(self, commands: Commands) -> None:
        self.commands = commands

    @classmethod
    async def install(cls, server: Server, commands: Commands, namespace_index: int) -> CommandsDoor:
        door = cls(commands)
        install_caller_context(server.iserver)
        ns = namespace_index
        obj = await server.nodes.objects.add_object(ua.NodeId(COMMANDS_OBJECT, ns), ua.QualifiedName(COMMANDS_OBJECT, ns))
        # Set in place: our attribute service lets nothing but tag values be written.
        server.iserver.aspace[obj.nodeid].attributes[ua.AttributeIds.Description] = AttributeValue(ua.DataValue(ua.Variant(
            ua.LocalizedText("The runtime's commands (alarms, ...), checked against the session's role"), ua.VariantType.LocalizedText)))
        await obj.add_method(
            ua.NodeId(f"{COMMANDS_OBJECT}.Call", ns), ua.QualifiedName("Call", ns), door._call,
            [_argument("name", "command name, e.g. alarms.acknowledge"), _argument("argumentsJSON", "a JSON object of its arguments")],
            [_argument("resultJSON", '{"ok": true, "result": ...} or {"ok": false, "error": "..."}')],
        )
        await obj.add_method(ua.NodeId(f"{COMMANDS_OBJECT}.List", ns), ua.QualifiedName("List", ns), door._list, [],
                             [_argument("commandsJSON", "every command: name, permission, description, arguments")])
        return door

    async def _call(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        origin = current_origin()
        if origin is None:
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        checked = _strings(arguments, 2)
        if isinstance(checked, ua.StatusCode):
            return checked
        name, text = checked
        try:
            parsed = json.loads(text) if text.strip() else {}
        except (ValueError, RecursionError):  # not JSON, or nested deeper than the parser goes
            return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
        if not isinstance(parsed, dict):
            return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
        status, result, refusal = await call_command(self.commands, name, parsed, origin)
        if status is not None:
            return status
        reply = {"ok": False, "error": str(refusal)} if refusal is not None else {"ok": True, "result": result}
        return [ua.Variant(json.dumps(reply, default=str), ua.VariantType.String)]

    async def _list(self, parent: ua.NodeId, *arguments: ua.Variant) -> Any:
        if arguments:
            return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
        listing = []
        for name in self.commands.names():
            command = self.commands.get(name)
            assert command is not None
            listing.append({"name": name, "permission": command.permission.value, "description": command.description,
                            "arguments": dict(command.arguments)})
        return [ua.Variant(json.dumps(listing), ua.VariantType.String)]


def _argument(name: str, description: str) -> ua.Argument:
    argument = ua.Argument()
    argument.Name = name
    argument.DataType = ua.NodeId(ua.ObjectIds.String)
    argument.ValueRank = -1
    argument.Description = ua.LocalizedText(description)
    return argument


def _strings(arguments: tuple[ua.Variant, ...], count: int) -> tuple[str, ...] | ua.StatusCode:
    if len(arguments) < count:
        return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
    if len(arguments) > count:
        return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
    values = tuple(getattr(argument, "Value", argument) for argument in arguments)
    if not all(isinstance(value, str) for value in values):
        return ua.StatusCode(ua.StatusCodes.BadTypeMismatch)
    return values  # type: ignore[return-value]

