"""The register image: the encoded value of every mapped tag, kept current cheaply.

The scan side only records which tags changed (`note_changed`, one list.extend per applied
batch); the encoding happens when a client reads (`refresh`), and only for tags that changed
since the last read. If nobody reads for a long time the backlog is capped: past one entry
per mapped tag it collapses into "re-encode everything", so memory stays bounded.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from softplc.modbus.address_map import AddressMap, Mapping, Table
from softplc.tagdb import TagDatabase
from softplc.tags import Tag

Writer = Callable[[Any], None]


class RegisterImage:
    """Per table, the words a read returns; coils and discrete inputs packed 16 per word, bit 0 first."""

    def __init__(self, address_map: AddressMap, db: TagDatabase) -> None:
        self.map = address_map
        self.words: dict[Table, list[int]] = {}
        for table in Table:
            size = address_map.size(table)
            self.words[table] = [0] * ((size + 15) // 16 if table.is_bit else size)
        # Keyed by the Tag object itself: identity hashing is the cheapest lookup on the hot path.
        self._writers: dict[Tag, Writer] = {}
        self._tags: list[Tag] = []
        for mapping in address_map.mappings:
            tag = db[mapping.name]
            self._writers[tag] = self._writer(mapping)
            self._tags.append(tag)
        self._dirty: list[Tag] = []
        self._all_dirty = True
        self._backlog_limit = max(1024, 2 * len(self._tags))

    def note_changed(self, changed: Sequence[Tag]) -> None:
        """Tag database callback: remember what changed (encoding waits for the next read)."""
        if self._all_dirty:
            return
        self._dirty.extend(changed)
        if len(self._dirty) > self._backlog_limit:
            self._dirty = []
            self._all_dirty = True

    def flush(self) -> None:
        """Encode every tag changed since the last flush into the image."""
        if self._all_dirty:
            self._all_dirty = False
            self._dirty = []
            for tag in self._tags:
                self._writers[tag](tag.value)
            return
        if not self._dirty:
            return
        dirty, self._dirty = self._dirty, []
        writers = self._writers
        for tag in dirty:
            writer = writers.get(tag)
            if writer is not None:
                writer(tag.value)

    def refresh(self, table: Table, first_word: int, count: int, target: list[int], target_offset: int) -> None:
        """Copy `count` current words of `table` from `first_word` into a pymodbus register block."""
        self.flush()
        target[target_offset : target_offset + count] = self.words[table][first_word : first_word + count]

    def _writer(self, mapping: Mapping) -> Writer:
        words = self.words[mapping.table]
        if mapping.codec is None:
            index, mask = divmod(mapping.address, 16)
            bit = 1 << mask

            def write_bit(value: Any) -> None:
                if value:
                    words[index] |= bit
                else:
                    words[index] &= ~bit

            return write_bit
        encode = mapping.codec.encode
        start, end = mapping.address, mapping.end

        def write_words(value: Any) -> None:
            words[start:end] = encode(value)

        return write_words
