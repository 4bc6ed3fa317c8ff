"""A bound tag's value and quality: what the remote said of it, what the link's health says, what the tag shows.

The rule (docs/links.md): a tag read from a remote is

- GOOD with the remote's value while the link delivers data and the remote says the value is good;
- UNCERTAIN (value kept) when no data came for 2x the link's period, BAD after 5x or when the link
  is down;
- BAD, keeping its last good value, with a reason, when the remote answered something the tag
  cannot hold: an exception code, garbage, a status that is not good, a value of another type or
  outside the tag's range. Never a wrong value with good quality.

`TagPublisher.publish` turns the bound tags whose shown (value, quality) would change into
journaled writes, validated by the tag database like any write (a value out of range comes back
refused: the tag goes BAD with the database's reason).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

from softplc.adapters.links.settings import Binding
from softplc.core.tagdb import Origin, TagDatabase
from softplc.core.tags import Quality

log = logging.getLogger(__name__)

_RANK = {Quality.GOOD: 0, Quality.UNCERTAIN: 1, Quality.BAD: 2}
NOT_READ = "not read from the remote yet"


def worse(first: Quality, second: Quality) -> Quality:
    return first if _RANK[first] >= _RANK[second] else second


@dataclass(eq=False)
class BoundTag:
    """One binding's state: the remote's last value and what it says of it, and what the tag was last given."""

    binding: Binding
    value: Any = None  # the remote's last value, decoded (None until read); for `out` tags the last value it took
    quality: Quality = Quality.BAD  # the remote's own verdict on `value` (GOOD unless a status, exception or range says otherwise)
    reason: str = NOT_READ  # why `quality` is not GOOD ("" when it is)
    shown: tuple[Any, Quality] | None = None  # the (value, quality) last journaled for the tag
    logged: str = ""  # the reason last logged, so each new reason is logged once
    refused: str = ""  # `out` and `both`: why the remote refused the last value sent ("" when it took it)

    @property
    def name(self) -> str:
        return self.binding.tag.name

    def good(self, value: Any) -> None:
        self.value, self.quality, self.reason = value, Quality.GOOD, ""

    def bad(self, reason: str, quality: Quality = Quality.BAD) -> None:
        """The remote's answer cannot be taken: keep the last value, say why."""
        self.quality, self.reason = quality, reason


class TagPublisher:
    """Journals bound tags' values and qualities for one link, with the link's origin."""

    def __init__(self, link: str, db: TagDatabase, origin: Origin) -> None:
        self.link = link
        self.db = db
        self.origin = origin

    def publish(self, tags: list[BoundTag], health: Quality) -> None:
        """Journal what changed of `tags`; `health` is the link's quality (GOOD, UNCERTAIN after 2x, BAD after 5x or down)."""
        values: dict[Quality, list[BoundTag]] = {}
        qualities: dict[Quality, list[BoundTag]] = {}
        for bound in tags:
            if bound.value is None or bound.quality is Quality.BAD:
                # Nothing trustworthy from the remote: the tag keeps its value and says BAD.
                if bound.shown is None or bound.shown[1] is not Quality.BAD:
                    qualities.setdefault(Quality.BAD, []).append(bound)
                continue
            quality = worse(bound.quality, health)
            shown = bound.shown
            if shown is None or shown[0] != bound.value or type(shown[0]) is not type(bound.value):
                values.setdefault(quality, []).append(bound)  # a new value from the remote
            elif shown[1] is not quality:
                # Only the verdict changed (the link went late, or is back): the tag keeps its value —
                # a `both` tag may have been changed here since, and a stale remote value must not undo that.
                qualities.setdefault(quality, []).append(bound)
        for quality, group in values.items():
            results = self.db.submit([(bound.name, bound.value) for bound in group], self.origin, quality=quality)
            for bound, rejected in zip(group, results):
                if rejected is None:
                    bound.shown = (bound.value, quality)
                    continue
                # Validated like any write: a value outside the tag's type or range is refused, never shown.
                bound.bad(f"the remote's value {bound.value!r} does not fit the tag: {rejected.detail}")
                qualities.setdefault(Quality.BAD, []).append(bound)
        for quality, group in qualities.items():
            self.db.submit_quality([bound.name for bound in group], quality, self.origin)
            for bound in group:
                bound.shown = (bound.shown[0] if bound.shown else None, quality)
        for bound in tags:
            self.log_reason(bound)

    def log_reason(self, bound: BoundTag) -> None:
        """Log a tag's reason once, when it changes (the log's flood filter limits a storm of different ones)."""
        reason = bound.reason if bound.quality is not Quality.GOOD and bound.reason != NOT_READ else ""
        if reason == bound.logged:
            return
        if reason:
            log.warning("link %s: %s is %s: %s", self.link, bound.name, bound.quality.value.upper(), reason)
        elif bound.logged:
            log.info("link %s: %s is good again", self.link, bound.name)
        bound.logged = reason
