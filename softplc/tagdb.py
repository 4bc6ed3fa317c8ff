"""The tag database: every tag's value, the write journal, and change notification.

Adapters (protocol servers, robots, the HMI) talk to the core only through this API:

- read a tag or a snapshot (`db[name]`, `db.snapshot(names)`);
- submit writes (`db.submit(...)`): each item is validated at once, exactly as a PLC validates
  a client write, and the valid ones are journaled and applied at the next cycle boundary;
- be told of changes (`db.on_change(callback)`), called after each batch is applied.

Programs' outputs are committed by the scan engine with `db.commit(...)`.
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from softplc.datatypes import TypeMismatch
from softplc.tags import Quality, Tag, TagDef

log = logging.getLogger(__name__)


class Rule(enum.Enum):
    """The rule a rejected write broke. Adapters map these to their protocol's status codes."""

    UNKNOWN_TAG = "unknown tag"
    READ_ONLY = "read-only"
    TYPE_MISMATCH = "type mismatch"
    OUT_OF_RANGE = "out of range"


class WriteRejected(Exception):
    """A write that broke a rule; nothing of it was applied."""

    def __init__(self, tag: str, rule: Rule, detail: str) -> None:
        super().__init__(f"{tag}: {rule.value}: {detail}")
        self.tag = tag
        self.rule = rule
        self.detail = detail


@dataclass(frozen=True, slots=True)
class Write:
    """One journaled write: a new value (and optionally a quality) for a tag."""

    tag: str
    value: Any
    source: str
    quality: Quality = Quality.GOOD


ChangeCallback = Callable[[Sequence[Tag]], None]


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
        self._journal: list[Write] = []
        self._callbacks: list[ChangeCallback] = []

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

    def validate(self, name: str, value: Any, *, client: bool = True) -> Any:
        """Return `value` coerced to the tag's type, or raise WriteRejected.

        `client=True` applies the access rule (ro tags are read-only for clients); programs
        and drivers inside the runtime pass `client=False`.
        """
        tag = self._tags.get(name)
        if tag is None:
            raise WriteRejected(name, Rule.UNKNOWN_TAG, "no such tag")
        definition = tag.definition
        if client and not definition.writable_by_clients:
            raise WriteRejected(name, Rule.READ_ONLY, "the tag is read-only for clients")
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

    # -- writing --------------------------------------------------------------------------

    def submit(
        self,
        items: Iterable[tuple[str, Any]],
        source: str,
        *,
        client: bool = True,
        quality: Quality = Quality.GOOD,
    ) -> list[WriteRejected | None]:
        """Validate each (tag, value) and journal the valid ones; one result per item.

        Journaled writes are applied by `apply_journal()` at the next cycle boundary, so a
        scan never sees half of an external write.
        """
        results: list[WriteRejected | None] = []
        for name, value in items:
            try:
                coerced = self.validate(name, value, client=client)
            except WriteRejected as rejected:
                results.append(rejected)
                continue
            self._journal.append(Write(name, coerced, source, quality))
            results.append(None)
        return results

    def submit_quality(self, names: Iterable[str], quality: Quality, source: str) -> None:
        """Journal a quality change (the value stays) for the named tags."""
        for name in names:
            tag = self._tags[name]
            self._journal.append(Write(name, tag.value, source, quality))

    @property
    def journal_length(self) -> int:
        return len(self._journal)

    def apply_journal(self) -> int:
        """Apply every journaled write in arrival order; return how many were applied."""
        if not self._journal:
            return 0
        journal, self._journal = self._journal, []
        now = self._now()
        changed: dict[str, Tag] = {}
        for write in journal:
            tag = self._tags[write.tag]
            # A journaled value was valid when submitted; the tag cannot change type since.
            if tag.value != write.value or tag.quality is not write.quality or type(tag.value) is not type(write.value):
                tag.value = write.value
                tag.quality = write.quality
                tag.timestamp = now
                changed[write.tag] = tag
        self._notify(list(changed.values()))
        return len(journal)

    def commit(self, values: Mapping[str, Any]) -> list[Tag]:
        """Apply already-validated values (a scan's outputs) at once; return the changed tags."""
        now = self._now()
        changed: list[Tag] = []
        tags = self._tags
        for name, value in values.items():
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

    def _notify(self, changed: list[Tag]) -> None:
        if not changed:
            return
        for callback in list(self._callbacks):
            try:
                callback(changed)
            except Exception:  # a broken subscriber must never stop the scan
                log.exception("tag change subscriber %r failed", callback)
