"""The tag database: every tag's value, the write journal, and change notification.

Adapters (protocol servers, robots, the HMI, the historian) talk to the core only through
this API:

- read a tag or a snapshot (`db[name]`, `db.snapshot(names)`);
- submit writes (`db.submit(items, origin)`): each item is validated at once, exactly as a PLC
  validates a client write — type, range, and what the writer's role may do — and the valid ones
  are journaled and applied at the next cycle boundary;
- be told of changes (`db.on_change(callback)`), called after each batch is applied;
- be told of every client write, accepted or refused, with its origin (`db.on_write(callback)`):
  the one place an audit trail or a write log listens, so no adapter keeps its own;
- force and unforce tags (`db.force`, `db.unforce`, `db.forces`; see `softplc/core/forcing.py`).

While the plant is not the active one of a redundant pair (`softplc/core/plant_role.py`), the
door is shut: client writes and forces are refused with rule NOT_ACTIVE, and internal writes
are dropped (the active's image is mirrored here instead, `softplc/engine/replication.py`).

Programs' outputs are committed by the scan engine with `db.commit(...)`.

One module of ~430 lines on purpose: the image, the journal, forcing's application and the door
share the same private state and its ordering rules (a write journaled, then applied at the
boundary, then notified); what a write is and the rules it may break are in `writes.py`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any

from softplc.core.datatypes import DataType, TypeMismatch
from softplc.core.forcing import Force, ForceChange, Forces
from softplc.core.origin import Origin, origin_of
from softplc.core.plant_role import RoleHolder
from softplc.core.roles import Role
from softplc.core.tags import Access, Quality, Tag, TagDef
from softplc.core.writes import KEEP_VALUE, Rule, Write, WriteEvent, WriteRejected

__all__ = ["KEEP_VALUE", "Origin", "Rule", "TagDatabase", "Write", "WriteEvent", "WriteRejected", "origin_of"]  # writes.py's too: the API of one place

log = logging.getLogger(__name__)

_PLAIN = {DataType.FLOAT64: float, DataType.BOOL: bool}


ChangeCallback = Callable[[Sequence[Tag]], None]
WriteCallback = Callable[[Sequence[WriteEvent]], None]
JournalCallback = Callable[[int, Sequence["Write | ForceChange"]], None]


class TagDatabase:
    """All tags of a plant, with a write journal applied between scan cycles."""

    def __init__(self, definitions: Iterable[TagDef], now: Callable[[], float]) -> None:
        self._now = now
        start = now()
        self._tags: dict[str, Tag] = {}
        for definition in definitions:
            if definition.name in self._tags:
                raise ValueError(f"duplicate tag {definition.name!r}")
            self._tags[definition.name] = Tag(definition, start)
        # Tags whose every value of one Python type is valid as it is (a float64 or a bool
        # without bounds): the runtime's own writes of that type need no conversion (`validate`).
        self._plain: dict[str, type] = {
            tag.name: plain for tag in self._tags.values()
            if (plain := _PLAIN.get(tag.definition.type)) is not None and tag.definition.min is None and tag.definition.max is None
        }
        self._journal: list[Write | ForceChange] = []
        self._callbacks: list[ChangeCallback] = []
        self._write_callbacks: list[WriteCallback] = []
        self._journal_callbacks: list[JournalCallback] = []
        self.forces = Forces()
        # Positions in the stream of every journal entry ever made: how many were journaled, and
        # how many applied (a standby resumes the active's journal from the applied position).
        self.journaled_position = 0
        self.applied_position = 0
        self.role: RoleHolder | None = None  # set by the runtime: writes are refused unless active

    # -- reading --------------------------------------------------------------------------

    def __getitem__(self, name: str) -> Tag:
        return self._tags[name]

    def __contains__(self, name: object) -> bool:
        return name in self._tags

    def __iter__(self) -> Iterator[Tag]:
        return iter(self._tags.values())

    def __len__(self) -> int:
        return len(self._tags)

    def get(self, name: str) -> Tag | None:
        return self._tags.get(name)

    def names(self) -> list[str]:
        return list(self._tags)

    def value(self, name: str) -> Any:
        return self._tags[name].value

    def snapshot(self, names: Iterable[str] | None = None) -> dict[str, Any]:
        """Values of the named tags (all tags if None), taken at one instant."""
        tags = self._tags
        if names is None:
            return {name: tag.value for name, tag in tags.items()}
        return {name: tags[name].value for name in names}

    # -- validation -----------------------------------------------------------------------

    def validate(self, name: str, value: Any, *, role: Role | None = Role.OPERATOR) -> Any:
        """Return `value` coerced to the tag's type, or raise WriteRejected.

        `role` is the writer's (see `softplc.core.roles`); `None` is code inside the runtime
        (programs, drivers), to which no access rule applies.
        """
        if role is None and type(value) is self._plain.get(name):
            return value  # what `coerce` would return: a robot's position, a program's flag
        tag = self._tags.get(name)
        if tag is None:
            raise WriteRejected(name, Rule.UNKNOWN_TAG, "no such tag")
        definition = tag.definition
        if role is not None:
            self._check_door(name)
            self._check_access(definition, role)
            if name in self.forces:
                raise WriteRejected(name, Rule.FORCED, "the tag is forced; unforce it first")
        try:
            coerced = definition.type.coerce(value)
        except TypeMismatch as error:
            raise WriteRejected(name, Rule.TYPE_MISMATCH, str(error)) from None
        if (definition.min is not None or definition.max is not None) and coerced != coerced:
            # NaN compares false with every bound, so it would slip past both checks below.
            raise WriteRejected(name, Rule.OUT_OF_RANGE, "NaN is outside the range of a bounded tag")
        if definition.min is not None and coerced < definition.min:
            raise WriteRejected(name, Rule.OUT_OF_RANGE, f"{coerced} is below the minimum {definition.min}")
        if definition.max is not None and coerced > definition.max:
            raise WriteRejected(name, Rule.OUT_OF_RANGE, f"{coerced} is above the maximum {definition.max}")
        return coerced

    def writable(self, name: str, role: Role) -> bool:
        """Whether a client with `role` may write the tag at all (for UserAccessLevel, HMI controls)."""
        try:
            self.check_access(name, role)
        except WriteRejected:
            return False
        return True

    def check_access(self, name: str, role: Role) -> None:
        """Raise WriteRejected if a client with `role` may not write the tag (whatever the value)."""
        tag = self._tags.get(name)
        if tag is None:
            raise WriteRejected(name, Rule.UNKNOWN_TAG, "no such tag")
        self._check_access(tag.definition, role)

    def _check_door(self, name: str) -> None:
        """Raise WriteRejected(NOT_ACTIVE) unless this plant is the active one (or alone)."""
        if self.role is not None:
            refusal = self.role.refusal()
            if refusal:
                raise WriteRejected(name, Rule.NOT_ACTIVE, refusal)

    @staticmethod
    def _check_access(definition: TagDef, role: Role) -> None:
        if definition.runtime_only:
            raise WriteRejected(definition.name, Rule.READ_ONLY, "a diagnostic tag, written by the runtime only")
        if not role.may_write:
            raise WriteRejected(definition.name, Rule.ACCESS_DENIED, f"role {role.value} may not write")
        if definition.access is Access.RO and not role.may_write_read_only:
            raise WriteRejected(definition.name, Rule.READ_ONLY, "the tag is read-only for clients")

    # -- writing --------------------------------------------------------------------------

    def submit(
        self,
        items: Iterable[tuple[str, Any]],
        origin: Origin | str,
        *,
        quality: Quality = Quality.GOOD,
        atomic: bool = False,
    ) -> list[WriteRejected | None]:
        """Validate each (tag, value) for `origin` and journal the valid ones; one result per item.

        Journaled writes are applied by `apply_journal()` at the next cycle boundary, so a
        scan never sees half of an external write. `atomic=True` journals nothing unless every
        item is valid (a Modbus request); the valid items then answer with the first refusal.
        A client's items (origin with a role) are reported to `on_write` listeners.
        """
        origin = origin_of(origin)
        items = list(items)
        role = origin.role
        if role is None and self.role is not None and not self.role.is_active():
            return self._submit_on_standby(items)
        accepted: list[Write] = []
        results: list[WriteRejected | None] = []
        for name, value in items:
            try:
                coerced = self.validate(name, value, role=role)
            except WriteRejected as rejected:
                results.append(rejected)
                continue
            accepted.append(Write(name, coerced, origin, quality))
            results.append(None)
        if atomic and len(accepted) < len(items):
            first = next(result for result in results if result is not None)
            results = [result or WriteRejected(name, first.rule, f"not applied: {first}") for (name, _), result in zip(items, results)]
            accepted = []
        if self._write_callbacks and role is not None:
            values = iter(accepted)
            now = self._now()
            events = []
            for (name, value), result in zip(items, results):
                tag = self._tags.get(name)
                old = tag.value if tag is not None else None
                if result is None:
                    events.append(WriteEvent(now, origin, name, old, next(values).value))
                else:
                    events.append(WriteEvent(now, origin, name, old, value, result.rule, result.detail))
            self._report(events)
        self._add_to_journal(accepted)
        return results

    def _submit_on_standby(self, items: list[tuple[str, Any]]) -> list[WriteRejected | None]:
        """A driver's write on a standby: the active's image is what counts here, except this runtime's own
        diagnostic tags (`_sys.`, never mirrored), which are set at once — a standby runs no cycle to apply them."""
        refusal = self.role.refusal() if self.role is not None else ""
        results: list[WriteRejected | None] = []
        own: dict[str, Any] = {}
        for name, value in items:
            tag = self._tags.get(name)
            if tag is None or not tag.definition.runtime_only or value is KEEP_VALUE:
                results.append(WriteRejected(name, Rule.NOT_ACTIVE, refusal))
                continue
            try:
                own[name] = self.validate(name, value, role=None)
            except WriteRejected as rejected:
                results.append(rejected)
                continue
            results.append(None)
        if own:
            self.commit(own)
        return results

    def refused(self, origin: Origin | str, name: str, value: Any, rule: Rule, detail: str) -> WriteRejected:
        """Report a write an adapter refused before it reached `submit` (e.g. a protocol rule); returns it."""
        origin = origin_of(origin)
        if self._write_callbacks and origin.role is not None:
            tag = self._tags.get(name)
            self._report([WriteEvent(self._now(), origin, name, tag.value if tag is not None else None, value, rule, detail)])
        return WriteRejected(name, rule, detail)

    def submit_quality(self, names: Iterable[str], quality: Quality, origin: Origin | str) -> None:
        """Journal a quality change (the value stays) for the named tags (drivers only).

        The value is the one the tag has when the change is applied: a value journaled before it
        (a driver's new reading in the same cycle) stands.
        """
        origin = origin_of(origin)
        if self.role is not None and not self.role.is_active():
            return
        for name in names:
            if name not in self._tags:
                raise KeyError(name)
        self._add_to_journal([Write(name, KEEP_VALUE, origin, quality) for name in names])

    def force(self, name: str, value: Any, origin: Origin | str) -> Any:
        """Force a tag to `value` from the next cycle boundary on; returns the coerced value.

        Raises WriteRejected for an unknown tag, a diagnostic tag, or a value that breaks the
        tag's type or range (a force is a value the process may have). Who may force is decided
        by the caller (the `tags.force` command needs the engineer role).
        """
        tag = self._tags.get(name)
        if tag is None:
            raise WriteRejected(name, Rule.UNKNOWN_TAG, "no such tag")
        if tag.definition.runtime_only:
            raise WriteRejected(name, Rule.READ_ONLY, "a diagnostic tag, written by the runtime only, cannot be forced")
        self._check_door(name)
        coerced = self.validate(name, value, role=None)
        self.forces.note_request(name)
        self._add_to_journal([ForceChange(name, True, coerced, origin_of(origin), self._now())])
        return coerced

    def unforce(self, name: str, *, restore: bool = False) -> bool:
        """Release a forced tag at the next cycle boundary (`restore`: back to its value before the force)."""
        if name not in self.forces and not self.forces.requested(name):
            return False
        self._check_door(name)
        self.forces.note_request(name)
        self._add_to_journal([ForceChange(name, False, restore=restore)])
        return True

    @property
    def journal_length(self) -> int:
        return len(self._journal)

    def pending(self) -> list[Write | ForceChange]:
        """The entries waiting for the next cycle boundary, from `applied_position` on (a standby that connects needs them)."""
        return list(self._journal)

    def _add_to_journal(self, entries: list[Write | ForceChange]) -> None:
        if not entries:
            return
        first = self.journaled_position
        self._journal.extend(entries)
        self.journaled_position = first + len(entries)
        for callback in self._journal_callbacks:
            try:
                callback(first, entries)
            except Exception:  # a broken listener must never refuse or lose a write
                log.exception("journal listener %r failed", callback)

    def on_journal(self, callback: JournalCallback) -> Callable[[], None]:
        """Call `callback(position, entries)` for every batch entering the write journal (a standby's copy); returns an undo.

        `position` is the stream position of the first entry. Called synchronously, before the
        writer is answered: an entry a listener has sent on is never acknowledged and then lost.
        """
        self._journal_callbacks.append(callback)
        return lambda: self._journal_callbacks.remove(callback) if callback in self._journal_callbacks else None

    def resume_journal(self, position: int, entries: Sequence[Write | ForceChange]) -> None:
        """Continue the journal of the active this plant mirrored: `entries` (not yet applied there) from `position` on."""
        self.discard_journal()
        self.applied_position = self.journaled_position = position
        for entry in entries:
            if type(entry) is ForceChange:
                self.forces.note_request(entry.tag)
        self._add_to_journal(list(entries))

    def discard_journal(self) -> None:
        """Forget the writes waiting for a cycle (a plant that became a standby: the active's image wins)."""
        self._journal = []
        self.forces.forget_requests()

    # -- mirroring (a standby of a redundant pair) -------------------------------------------

    def mirror(self, values: Iterable[tuple[str, Any, Quality, float]]) -> list[Tag]:
        """Set tags to the active's (value, quality, timestamp) as they are; return the changed tags.

        Only for a standby copying the active's image: nothing is validated (the active did it) and
        forces are not consulted (the active's forced values come with the image).
        """
        changed = []
        tags = self._tags
        for name, value, quality, timestamp in values:
            tag = tags[name]
            if tag.value != value or tag.quality is not quality or type(tag.value) is not type(value):
                tag.value = value
                tag.quality = quality
                tag.timestamp = timestamp
                changed.append(tag)
        self._notify(changed)
        return changed

    def mirror_forces(self, forces: Sequence[Force]) -> None:
        """Make the forces in effect exactly `forces` (the active's), marking the tags."""
        wanted = {force.tag: force for force in forces if force.tag in self._tags}
        changed = []
        for force in self.forces.active():
            if force.tag not in wanted:
                tag = self._tags[force.tag]
                tag.forced = False
                changed.append(tag)
        self.forces.replace(list(wanted.values()))
        for name in wanted:
            tag = self._tags[name]
            if not tag.forced:
                tag.forced = True
                changed.append(tag)
        self._notify(changed)

    def apply_journal(self) -> int:
        """Apply forces, then every journaled write in arrival order; return how many were applied.

        Writes to a forced tag are dropped (a driver's; a client's was refused when submitted).
        """
        if not self._journal:
            return 0
        journal, self._journal = self._journal, []
        self.applied_position += len(journal)
        now = self._now()
        changed: dict[str, Tag] = {}
        forces = self.forces
        for write in journal:
            if type(write) is ForceChange:
                self._apply_force(write, now, changed)
                continue
            if write.tag in forces:
                continue
            tag = self._tags[write.tag]
            value = tag.value if write.value is KEEP_VALUE else write.value
            # A journaled value was valid when submitted; the tag cannot change type since.
            if tag.value != value or tag.quality is not write.quality or type(tag.value) is not type(value):
                tag.value = value
                tag.quality = write.quality
                tag.timestamp = now
                changed[write.tag] = tag
        self._notify(list(changed.values()))
        return len(journal)

    def _apply_force(self, change: ForceChange, now: float, changed: dict[str, Tag]) -> None:
        tag = self._tags[change.tag]
        released = self.forces.apply(change, tag.value)
        if change.force:
            tag.forced = True
            tag.value = change.value
        elif released is not None:
            tag.forced = False
            if change.restore:
                tag.value = released.previous
        else:
            return
        tag.timestamp = now
        changed[change.tag] = tag

    def commit(self, values: Mapping[str, Any]) -> list[Tag]:
        """Apply already-validated values (a scan's outputs) at once; return the changed tags.

        Outputs to forced tags are dropped: the forced value stands.
        """
        now = self._now()
        changed: list[Tag] = []
        tags = self._tags
        forces = self.forces
        for name, value in values.items():
            if forces and name in forces:
                continue
            tag = tags[name]
            if tag.value != value or tag.quality is not Quality.GOOD or type(tag.value) is not type(value):
                tag.value = value
                tag.quality = Quality.GOOD
                tag.timestamp = now
                changed.append(tag)
        self._notify(changed)
        return changed

    # -- change notification --------------------------------------------------------------

    def on_change(self, callback: ChangeCallback) -> Callable[[], None]:
        """Call `callback(changed_tags)` after every applied batch; returns an unsubscribe."""
        self._callbacks.append(callback)
        return lambda: self._callbacks.remove(callback)

    def on_write(self, callback: WriteCallback) -> Callable[[], None]:
        """Call `callback(events)` for every client write, accepted or refused; returns an unsubscribe.

        Called synchronously from `submit` on the event loop: keep it cheap (queue, don't write files).
        """
        self._write_callbacks.append(callback)
        return lambda: self._write_callbacks.remove(callback)

    def _report(self, events: list[WriteEvent]) -> None:
        for callback in list(self._write_callbacks):
            try:
                callback(events)
            except Exception:  # a broken listener must never refuse or lose a write
                log.exception("write listener %r failed", callback)

    def _notify(self, changed: list[Tag]) -> None:
        if not changed:
            return
        for callback in list(self._callbacks):
            try:
                callback(changed)
            except Exception:  # a broken subscriber must never stop the scan
                log.exception("tag change subscriber %r failed", callback)
