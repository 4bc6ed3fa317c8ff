"""Expressions of user views, evaluated on the server: one implementation (`softplc.core.expression`).

Each distinct expression is a live item named "=<expression>" (tag names never start with "=").
When a tag changes, only the expressions that read it are evaluated again; an expression's
quality is the worst of its tags' (a robot away makes its marker's condition BAD too), and one
that cannot be evaluated (text compared with a number...) is BAD with no value, logged once.
While no browser watches anything the live channel skips that work: it marks the table stale
(`stale = True`), and the next subscription re-evaluates every expression (`refresh()`) before
its snapshot, so a snapshot never shows a value from before the changes nobody watched.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Any

from softplc.core.expression import Condition
from softplc.core.tagdb import TagDatabase
from softplc.core.tags import Quality, Tag

log = logging.getLogger(__name__)

_WORST = {Quality.GOOD: 0, Quality.UNCERTAIN: 1, Quality.BAD: 2}


class Item:
    """An expression's current value, with a quality and timestamp like a tag's."""

    __slots__ = ("name", "value", "quality", "timestamp")
    forced = False  # an expression is never forced itself (its tags may be)

    def __init__(self, name: str, value: Any, quality: Quality, timestamp: float) -> None:
        self.name = name
        self.value = value
        self.quality = quality
        self.timestamp = timestamp


class ExpressionTable:
    """The current value of every view expression, kept up to date from tag changes."""

    def __init__(self, db: TagDatabase, conditions: dict[str, Condition], now: Callable[[], float]) -> None:
        self._db = db
        self._now = now
        self._conditions = dict(conditions)
        self._readers: dict[str, list[str]] = {}  # tag → expressions that read it
        for key, condition in self._conditions.items():
            for name in condition.names:
                self._readers.setdefault(name, []).append(key)
        self._read = frozenset(db[name] for name in self._readers)  # the tags some expression reads
        self._items: dict[str, Item] = {}
        self._failed: set[str] = set()
        self.stale = False  # tags changed without being looked at (nobody watched): refresh() before reading
        for key in self._conditions:
            value, quality = self._evaluate(key)
            self._items[key] = Item(key, value, quality, self._stamp(key))

    def __contains__(self, key: object) -> bool:
        return key in self._items

    def get(self, key: str) -> Item | None:
        return self._items.get(key)

    def changed(self, tags: set[Tag]) -> list[Item]:
        """Re-evaluate the expressions that read any of `tags`; return those whose value or quality changed."""
        read = self._read & tags  # C speed: a scan may change thousands of tags, expressions read a few
        if not read:
            return []
        due: dict[str, None] = {}
        for tag in read:
            for key in self._readers[tag.name]:
                due[key] = None
        return self._refresh(due)

    def refresh(self) -> list[Item]:
        """Evaluate every expression again (after changes nobody watched); return those whose value or quality changed."""
        self.stale = False
        return self._refresh(self._conditions)

    def _refresh(self, keys: Iterable[str]) -> list[Item]:
        changed = []
        for key in keys:
            item = self._items[key]
            value, quality = self._evaluate(key)
            if value != item.value or quality is not item.quality or type(value) is not type(item.value):
                item.value, item.quality, item.timestamp = value, quality, self._stamp(key)
                changed.append(item)
        return changed

    def _stamp(self, key: str) -> float:
        """When the value last changed: the newest timestamp of the tags it reads (now, if it reads none)."""
        db = self._db
        return max((db[name].timestamp for name in self._conditions[key].names), default=self._now())

    def _evaluate(self, key: str) -> tuple[Any, Quality]:
        condition = self._conditions[key]
        db = self._db
        worst = Quality.GOOD
        for name in condition.names:
            quality = db[name].quality
            if _WORST[quality] > _WORST[worst]:
                worst = quality
        try:
            value = condition.value(db.value)
        except Exception as error:  # a user's expression: say once what is wrong, never stop the HMI
            if key not in self._failed:
                self._failed.add(key)
                log.warning("HMI view expression %r cannot be evaluated: %s: %s", condition.text, type(error).__name__, error)
            return None, Quality.BAD
        self._failed.discard(key)
        return value, worst
