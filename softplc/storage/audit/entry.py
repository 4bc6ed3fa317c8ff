"""One entry of the audit trail: a client's write of a tag, or a call of a command, accepted or refused.

The recorder queues the core's own objects on the event loop (`WriteEvent`s as `db.on_write`
hands them over, `CallRecord`s for `commands.on_call`); they become rows (`row_of`) on the
storage writer's thread, so the loop never encodes a value.
"""

from __future__ import annotations

import json
import json.encoder
import math
from dataclasses import asdict, dataclass
from typing import Any

from softplc.core.commands import CommandCall
from softplc.core.tagdb import WriteEvent
from softplc.util.timestamps import format_utc

MAX_TEXT = 4096  # longest value, argument list or detail kept (a client may send megabytes)
MAX_REFUSED = 512  # of a refused entry (what anyone, a viewer included, can send by the thousand): its value, arguments, detail
MAX_NAME = 256  # longest tag or command name kept (a refused one may be anything a client typed)
_string = json.encoder.encode_basestring  # a str as JSON text, in C (as json.dumps(..., ensure_ascii=False))
WRITE, COMMAND = "write", "command"


@dataclass(frozen=True)
class AuditEntry:
    """One row of the audit trail."""

    time: float  # wall-clock seconds of the runtime clock (simulated time under --sim)
    plant: str
    kind: str  # "write" or "command"
    source: str  # the path it came by: opcua, modbus, hmi, cli...
    user: str  # "" when the protocol has no logins (Modbus)
    peer: str  # the client's host:port, when the protocol knows it
    role: str  # viewer, operator, engineer
    name: str  # the tag written, or the command called
    tag: str  # the tag concerned: the one written, or a command's `tag` argument ("" if none)
    arguments: Any  # a command's arguments (a dict); None for a write
    old: Any  # the tag's value when the write or command arrived
    new: Any  # the value asked for
    accepted: bool
    rule: str  # the rule broken when refused (out of range, read-only, access denied...); "" when accepted
    detail: str  # why it was refused, or what a command did

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, with the time also as ISO 8601 UTC (`time_utc`)."""
        return {"time_utc": format_utc(self.time), **asdict(self)}

    @classmethod
    def from_dict(cls, row: dict[str, Any]) -> AuditEntry:
        """An entry received as JSON (the commands door)."""
        return cls(**{name: row[name] for name in COLUMNS})


COLUMNS = tuple(AuditEntry.__dataclass_fields__)


@dataclass(frozen=True, slots=True)
class CallRecord:
    """A command call as queued by the recorder: the call, plus what only the loop could tell."""

    call: CommandCall
    tag: str  # its `tag` argument when that names a tag
    old: Any  # that tag's value when the call was reported
    new: Any  # its `value` argument, parsed by the tag's type when given as text (a force from the CLI)
    rule: str  # "" when carried out; access denied, unknown command, refused


def row_of(item: WriteEvent | CallRecord, plant: str, sequence: int) -> tuple[Any, ...]:
    """The store's row for a queued item (on the writer thread): columns of `store.SQL_COLUMNS`."""
    if type(item) is WriteEvent:
        origin = item.origin
        role = origin.role.value if origin.role is not None else ""
        if item.rule is None:
            return (item.time, plant, WRITE, origin.source, origin.user, origin.peer, role, item.tag, item.tag, None,
                    encode(item.old), encode(item.new), 1, "", _clip(item.detail), sequence)
        name = _clip(item.tag, MAX_NAME)
        return (item.time, plant, WRITE, origin.source, origin.user, origin.peer, role, name, name, None,
                encode(item.old), encode(item.new, MAX_REFUSED), 0, item.rule.value, _clip(item.detail, MAX_REFUSED), sequence)
    call = item.call
    origin = call.origin
    role = origin.role.value if origin.role is not None else ""
    limit = MAX_TEXT if call.accepted else MAX_REFUSED
    return (call.time, plant, COMMAND, origin.source, origin.user, origin.peer, role, _clip(call.command, MAX_NAME), item.tag,
            encode(dict(call.arguments), limit), encode(item.old) if item.tag else None, encode(item.new, limit) if item.tag else None,
            1 if call.accepted else 0, item.rule, _clip(str(call.detail), limit), sequence)


def entry_of(row: tuple[Any, ...]) -> AuditEntry:
    """An entry from a stored row (columns of `store.SQL_COLUMNS`, without the sequence)."""
    time, plant, kind, source, user, peer, role, name, tag, arguments, old, new, accepted, rule, detail = row[:15]
    return AuditEntry(float(time), plant, kind, source, user, peer, role, name, tag, decode(arguments), decode(old), decode(new),
                      bool(accepted), rule, detail)


def encode(value: Any, limit: int = MAX_TEXT) -> str | None:
    """A value as JSON text (None stays NULL); anything a client sent is kept as text, clipped to `limit` characters."""
    # Tag values first, without json.dumps (a third of a row's cost at 10,000 entries a second).
    kind = type(value)
    if kind is int:
        return int.__repr__(value)
    if kind is float:
        if value - value == 0.0:  # finite (JSON has no inf or NaN: those take the long way)
            return float.__repr__(value)
    elif kind is bool:
        return "true" if value else "false"
    elif kind is str:
        if len(value) <= limit:
            return _string(value)
    elif value is None:
        return None
    try:
        text = json.dumps(value, ensure_ascii=False, default=str, allow_nan=True)
    except (TypeError, ValueError):  # a circular structure: cannot come from a protocol, but never fail a row
        text = json.dumps(repr(value))
    except RecursionError:  # nested deeper than the writer's stack: never fail a row either
        text = json.dumps(f"(a {type(value).__name__} nested too deeply to be written)")
    if len(text) > limit:
        text = json.dumps(f"{text[:limit]}… ({len(text)} characters)", ensure_ascii=False)
    return text


def decode(text: str | None) -> Any:
    if text is None:
        return None
    try:
        return json.loads(text)
    except ValueError:
        return text


def _clip(text: str, limit: int = MAX_TEXT) -> str:
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"


def format_value(value: Any) -> str:
    """A value for a table or CSV cell: text as it is, numbers and booleans as JSON writes them."""
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return json.dumps(value, ensure_ascii=False, default=str)
