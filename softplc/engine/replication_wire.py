"""The plant API's door to replication (`plant.replication`): states and journal entries as plain, checked data.

An adapter moving state between two runtimes (softplc/adapters/redundancy/) sees lists, numbers,
text and bytes only — nothing of the engine's classes — and whatever comes back from the other
side is checked here, field by field, before anything of it is applied: a malformed state or
journal entry raises `StateRefused` with the reason and changes nothing.

    ["state", sequence, full, task, time, journal, tags, forces, programs, parts]
        tags:     [[name, value, quality, timestamp], ...]
        parts:    {name: the part's own plain data}  (each checked by its adapter: `Plant.replicate`)
        forces:   None (unchanged) | [[tag, value, origin, since, previous], ...]
        programs: [[name, status, error, faults, restarts, version, retry_in | None, state bytes | None], ...]
    ["journal", position, [["w", tag, value, quality, origin] | ["f", tag, force, value, origin | None, since, restore], ...]]
        origin:   [source, user, peer, role | None]
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from softplc.core.datatypes import DataType, TypeMismatch
from softplc.core.forcing import Force, ForceChange
from softplc.core.origin import Origin
from softplc.core.plant import StateRefused, TaskView
from softplc.core.roles import Role
from softplc.core.tagdb import KEEP_VALUE, TagDatabase, Write
from softplc.core.tags import Quality
from softplc.engine.program_instance import ProgramState
from softplc.engine.program_state import ProgramStateError
from softplc.engine.replication import SYSTEM_PREFIX, CycleState, ProgramImage, Replication, ReplicationError

_QUALITIES = {quality.value: quality for quality in Quality}
_ROLES = {role.value: role for role in Role}
_STATUSES = {state.value for state in ProgramState}


class ReplicationDoor:
    """What `plant.replication` is: capture and apply a plant's state as plain data (see the module docstring)."""

    def __init__(self, replication: Replication) -> None:
        self.replication = replication
        self.db = replication.db
        self._kinds = replicated_types(self.db)  # a database's tags are fixed when it is made

    @property
    def sequence(self) -> int:
        return self.replication.sequence

    @property
    def held(self) -> int:
        """Journal entries of the active held here (a standby) until a state says they were applied."""
        return self.replication.held

    @property
    def unpicklable(self) -> dict[str, str]:
        return dict(self.replication.unpicklable)

    def capture(self, task: TaskView | None) -> list[Any]:
        return state_to_wire(self.replication.capture(task))  # type: ignore[arg-type]

    def capture_full(self) -> list[Any]:
        return state_to_wire(self.replication.capture_full())

    def apply(self, data: Any) -> None:
        state = state_from_wire(data, self.db, self._kinds)
        try:
            self.replication.apply(state)
        except (ReplicationError, ProgramStateError) as error:
            raise StateRefused(str(error)) from None

    def pending_journal(self) -> list[Any]:
        """The entries journaled and not yet applied, as a journal message (sent after a full state)."""
        return journal_to_wire(self.db.applied_position, self.db.pending())

    def on_journal(self, callback: Callable[[list[Any]], None]) -> Callable[[], None]:
        """Call `callback(journal_message)` for every batch entering the write journal (before the writer is answered).

        A batch of this runtime's own `_sys.` tags only (an adapter's status) is not the plant's: not sent."""
        def send(position: int, entries: Sequence[Write | ForceChange]) -> None:
            if not all(entry.tag.startswith(SYSTEM_PREFIX) for entry in entries):
                callback(journal_to_wire(position, entries))

        return self.db.on_journal(send)

    def hold(self, data: Any) -> None:
        position, entries = journal_from_wire(data, self.db)
        self.replication.hold(position, entries)

    def take_over(self) -> int:
        return self.replication.take_over()

    def add_part(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                 apply: Callable[[Any], None]) -> Callable[[], None]:
        return self.replication.add_part(name, capture, check, apply)


SKIPPED = "-"  # a journal entry of the active's own `_sys.` tags: it only keeps its place (positions count every entry)


# -- to the wire ---------------------------------------------------------------------------

def _origin(origin: Origin | None) -> list[Any] | None:
    if origin is None:
        return None
    return [origin.source, origin.user, origin.peer, origin.role.value if origin.role is not None else None]


def state_to_wire(state: CycleState) -> list[Any]:
    forces = None
    if state.forces is not None:
        forces = [[force.tag, force.value, _origin(force.origin), force.since, force.previous] for force in state.forces]
    programs = [[image.name, image.status, image.error, image.faults, image.restarts, image.version, image.retry_in, image.state]
                for image in state.programs]
    tags = [[name, value, quality.value, timestamp] for name, value, quality, timestamp in state.tags]
    return ["state", state.sequence, state.full, state.task, state.time, state.journal, tags, forces, programs, state.parts]


def journal_to_wire(position: int, entries: Sequence[Write | ForceChange]) -> list[Any]:
    items: list[list[Any]] = []
    for entry in entries:
        if entry.tag.startswith(SYSTEM_PREFIX):
            items.append([SKIPPED])  # this runtime's own status: it keeps its place in the journal, nothing more
        elif type(entry) is ForceChange:
            items.append(["f", entry.tag, entry.force, entry.value, _origin(entry.origin), entry.since, entry.restore])
        else:
            assert isinstance(entry, Write)
            if entry.value is KEEP_VALUE:  # a quality change: the value stays what it is when applied
                items.append(["q", entry.tag, entry.quality.value, _origin(entry.origin)])
            else:
                items.append(["w", entry.tag, entry.value, entry.quality.value, _origin(entry.origin)])
    return ["journal", position, items]


# -- from the wire -------------------------------------------------------------------------

def _list(value: Any, length: int | None, what: str) -> list[Any]:
    if not isinstance(value, (list, tuple)) or (length is not None and len(value) != length):
        size = f" of {length}" if length is not None else ""
        raise StateRefused(f"{what}: expected a list{size}, got {type(value).__name__}")
    return list(value)


def _typed(value: Any, kinds: type | tuple[type, ...], what: str) -> Any:
    if isinstance(value, bool) and bool not in (kinds if isinstance(kinds, tuple) else (kinds,)):
        raise StateRefused(f"{what}: expected {kinds}, got a bool")
    if not isinstance(value, kinds):
        raise StateRefused(f"{what}: expected {getattr(kinds, '__name__', kinds)}, got {type(value).__name__}")
    return value


def _number(value: Any, what: str) -> float:
    number = float(_typed(value, (int, float), what))
    if not math.isfinite(number):
        raise StateRefused(f"{what}: not a finite number")
    return number


def _tag_value(db: TagDatabase, name: Any, value: Any, what: str) -> tuple[str, Any]:
    name = _typed(name, str, what)
    tag = db.get(name)
    if tag is None or name.startswith(SYSTEM_PREFIX):
        raise StateRefused(f"{what}: no replicated tag {name!r} in this plant")
    try:
        return name, tag.definition.type.coerce(value)
    except TypeMismatch as error:
        raise StateRefused(f"{what}: {name}: {error}") from None


def _origin_from(data: Any, what: str) -> Origin:
    source, user, peer, role = _list(data, 4, what)
    if role is not None and role not in _ROLES:
        raise StateRefused(f"{what}: unknown role {role!r}")
    return Origin(_typed(source, str, what), _typed(user, str, what), _typed(peer, str, what), _ROLES[role] if role is not None else None)


def _quality(value: Any, what: str) -> Quality:
    if value not in _QUALITIES:
        raise StateRefused(f"{what}: unknown quality {value!r}")
    return _QUALITIES[value]


_INTEGER_LIMITS = {kind: kind.limits for kind in DataType if kind.is_integer}
def replicated_types(db: TagDatabase) -> dict[str, DataType]:
    """Each replicated tag's type (every tag but `_sys.`)."""
    return {tag.name: tag.definition.type for tag in db if not tag.name.startswith(SYSTEM_PREFIX)}


def _exact(kind: DataType, value: Any) -> bool:
    """`value` is already what `kind.coerce` would return, unchanged (float32 and strings always take the full check)."""
    kind_of = type(value)
    if kind is DataType.FLOAT64:  # (state_from_wire checks this one inline, before calling)
        return kind_of is float
    if kind is DataType.BOOL:
        return kind_of is bool
    if kind_of is int and kind in _INTEGER_LIMITS:
        low, high = _INTEGER_LIMITS[kind]
        return low <= value <= high
    return False


def state_from_wire(data: Any, db: TagDatabase, kinds: Mapping[str, DataType] | None = None) -> CycleState:
    """A CycleState from its plain form; raises StateRefused for anything malformed (see the module docstring).

    `kinds`: `replicated_types(db)`, when the caller keeps it between states."""
    kind, sequence, full, task, time, journal, tags, forces, programs, parts = _list(data, 10, "state")
    if kind != "state":
        raise StateRefused(f"not a state message: {kind!r}")
    state = CycleState(int(_typed(sequence, int, "sequence")), _typed(full, bool, "full"), _typed(task, str, "task"),
                       _number(time, "time"), int(_typed(journal, int, "journal")))
    kinds = kinds if kinds is not None else replicated_types(db)
    qualities, finite, append, float64 = _QUALITIES, math.isfinite, state.tags.append, DataType.FLOAT64
    for index, item in enumerate(_list(tags, None, "tags")):
        # The common case checked inline (a 10,000-tag state is 10,000 of these): a list of four, a
        # known tag's name, a value already of its exact type (a float64's float, a bool, an integer
        # in range), a known quality, a finite float time. Anything else takes the path that says why.
        if type(item) is list and len(item) == 4:
            name, value, quality, timestamp = item
            kind = kinds.get(name) if type(name) is str else None
            if (kind is not None and type(timestamp) is float and finite(timestamp) and quality in qualities
                    and ((kind is float64 and type(value) is float) or _exact(kind, value))):
                append((name, value, qualities[quality], timestamp))
                continue
        name, value, quality, timestamp = _list(item, 4, f"tag {index}")
        name, value = _tag_value(db, name, value, f"tag {index}")
        append((name, value, _quality(quality, f"tag {name}"), _number(timestamp, f"tag {name}")))
    if forces is not None:
        state.forces = []
        for index, item in enumerate(_list(forces, None, "forces")):
            tag, value, origin, since, previous = _list(item, 5, f"force {index}")
            tag, value = _tag_value(db, tag, value, f"force {index}")
            _, previous = _tag_value(db, tag, previous, f"force {index} (previous value)")
            state.forces.append(Force(tag, value, _origin_from(origin, f"force {tag}"), _number(since, f"force {tag}"), previous))
    for index, item in enumerate(_list(programs, None, "programs")):
        name, status, error, faults, restarts, version, retry_in, blob = _list(item, 8, f"program {index}")
        what = f"program {name!r}"
        if status not in _STATUSES:
            raise StateRefused(f"{what}: unknown state {status!r}")
        state.programs.append(ProgramImage(
            _typed(name, str, what), status, _typed(error, str, what), int(_typed(faults, int, what)),
            int(_typed(restarts, int, what)), int(_typed(version, int, what)),
            None if retry_in is None else _number(retry_in, what), None if blob is None else bytes(_typed(blob, (bytes, bytearray), what)),
        ))
    if not isinstance(parts, dict) or not all(isinstance(name, str) for name in parts):
        raise StateRefused("parts: expected a mapping of names")
    state.parts = dict(parts)
    return state


def journal_from_wire(data: Any, db: TagDatabase) -> tuple[int, list[Write | ForceChange | None]]:
    """The position and entries of a journal message (None: the active's own status, skipped); raises StateRefused for anything malformed."""
    kind, position, items = _list(data, 3, "journal")
    if kind != "journal":
        raise StateRefused(f"not a journal message: {kind!r}")
    entries: list[Write | ForceChange | None] = []
    for index, item in enumerate(_list(items, None, "journal entries")):
        item = _list(item, None, f"journal entry {index}")
        if item == [SKIPPED]:
            entries.append(None)
        elif item and item[0] == "w" and len(item) == 5:
            _, tag, value, quality, origin = item
            tag, value = _tag_value(db, tag, value, f"journal entry {index}")
            entries.append(Write(tag, value, _origin_from(origin, f"journal entry {index}"), _quality(quality, f"journal entry {index}")))
        elif item and item[0] == "q" and len(item) == 4:
            _, tag, quality, origin = item
            tag = _typed(tag, str, f"journal entry {index}")
            if tag not in db or tag.startswith(SYSTEM_PREFIX):
                raise StateRefused(f"journal entry {index}: no replicated tag {tag!r} in this plant")
            entries.append(Write(tag, KEEP_VALUE, _origin_from(origin, f"journal entry {index}"), _quality(quality, f"journal entry {index}")))
        elif item and item[0] == "f" and len(item) == 7:
            _, tag, force, value, origin, since, restore = item
            force = _typed(force, bool, f"journal entry {index}")
            if force:
                tag, value = _tag_value(db, tag, value, f"journal entry {index}")
            elif not isinstance(tag, str) or tag not in db:
                raise StateRefused(f"journal entry {index}: no tag {tag!r} in this plant")
            entries.append(ForceChange(tag, force, value if force else None,
                                       _origin_from(origin, f"journal entry {index}") if origin is not None else None,
                                       _number(since, f"journal entry {index}"), _typed(restore, bool, f"journal entry {index}")))
        else:
            raise StateRefused(f"journal entry {index}: neither a write nor a force")
    return int(_typed(position, int, "journal position")), entries
