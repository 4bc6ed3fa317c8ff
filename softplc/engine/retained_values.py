"""Retained tags across restarts: loaded at start, their changes saved once a second and at stop.

The store itself (SQLite, what a corrupt file does) is `softplc/engine/retain.py`; this is its
use by a running plant: which values come back (checked like any write), which changes are
noted (never a forced value) and when they reach the disk (off the event loop while scanning).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from softplc.core.clock import Clock
from softplc.core.tagdb import TagDatabase, WriteRejected
from softplc.engine.retain import RetainStore, open_retained
from softplc.util.plurals import plural

log = logging.getLogger("softplc.app.runtime")  # the runtime's messages, as they always were


class RetainedValues:
    """The retained tags of one tag database and their store (`path`, opened by `load`)."""

    def __init__(self, db: TagDatabase, clock: Clock, path: Path, corrupt: str) -> None:
        self.db = db
        self.clock = clock
        self.path = path
        self.corrupt = corrupt  # what a corrupt store does: "refuse" (raise) or "initial" (set aside)
        self.store: RetainStore | None = None
        self._dirty: dict[str, tuple[str, Any]] = {}  # tag → (type name, value) to save

    def load(self) -> None:
        """Restore the retained tags' saved values (raises RetainError for a store it may not use)."""
        retained = [tag for tag in self.db if tag.definition.retain]
        if not retained:
            return
        self.store, stored = open_retained(self.path, self.corrupt, self.clock.wall())
        values: dict[str, Any] = {}
        for tag in retained:
            if tag.name not in stored:
                continue
            type_name, value = stored[tag.name]
            try:
                # The same rules as any write (type, min/max, text): the configuration may have
                # changed since the value was saved, and a stored file is input like any other.
                values[tag.name] = self.db.validate(tag.name, value, role=None)
            except WriteRejected as rejected:
                log.warning("retained value %r of %s (saved as %s) is refused: %s: %s; %s starts at its initial value %r",
                            value, tag.name, type_name, rejected.rule.value, rejected.detail, tag.name, tag.definition.initial)
        self.db.commit(values)
        if values:
            log.info("restored %s from %s", plural(len(values), "retained tag value"), self.store.path)
        self.db.on_change(self._note)

    def _note(self, changed: Any) -> None:
        for tag in changed:
            if tag.definition.retain and not tag.forced:  # forces are not retained (softplc/core/forcing.py)
                # The value now, on the loop thread: the saving thread never reads a changing tag,
                # and a force applied later never reaches the store.
                self._dirty[tag.name] = (tag.definition.type.value, tag.value)

    async def save(self) -> None:
        """Save the changes since the last save, off the event loop: the SQLite commit waits for the disk."""
        if self.store is None or not self._dirty:
            return
        dirty, self._dirty = self._dirty, {}
        try:
            await self.clock.run_blocking(self.store.save, dirty)
        except Exception as error:
            log.error("cannot save retained values to %s: %s", self.store.path, error)
            self._dirty = {**dirty, **self._dirty}  # newer changes win

    def close(self) -> None:
        """Save what is left now (at stop, on the loop: nothing scans any more), then close the store."""
        if self.store is None:
            return
        if self._dirty:
            dirty, self._dirty = self._dirty, {}
            try:
                self.store.save(dirty)
            except Exception as error:
                log.error("cannot save retained values to %s: %s", self.store.path, error)
        self.store.close()
