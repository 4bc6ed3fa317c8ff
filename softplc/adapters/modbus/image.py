"""The register image: the encoded value of every mapped tag, kept current cheaply.

The scan side only records which tags changed (`note_changed`: one list.extend per applied
batch). Encoding waits for a read, and then covers only the tags inside the requested range
that changed since they were last encoded — a read costs at most ~125 encodings however many
tags the scans changed. If nobody reads for a long time the backlog of changes is capped: past
two entries per mapped tag it collapses into "every tag is stale", so memory stays bounded.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from softplc.adapters.modbus.address_map import AddressMap, Mapping, Table
from softplc.core.tagdb import TagDatabase
from softplc.core.tags import Tag

Writer = Callable[[Any], None]


class RegisterImage:
    """Per table, the words a read returns; coils and discrete inputs packed 16 per word, bit 0 first."""

    def __init__(self, address_map: AddressMap, db: TagDatabase) -> None:
        self.map = address_map
        self.words: dict[Table, list[int]] = {}
        for table in Table:
            size = address_map.size(table)
            self.words[table] = [0] * ((size + 15) // 16 if table.is_bit else size)
        count = len(address_map.mappings)
        self._tags: list[Tag] = [db[mapping.name] for mapping in address_map.mappings]
        self._writers: list[Writer] = [self._writer(mapping) for mapping in address_map.mappings]
        # Keyed by the Tag object itself: identity hashing is the cheapest lookup.
        self._index: dict[Tag, int] = {tag: index for index, tag in enumerate(self._tags)}
        self._stale = bytearray(b"\x01") * count  # per mapping: its words are out of date
        self._backlog: list[Tag] = []
        self._backlog_limit = max(1024, 2 * count)

    def note_changed(self, changed: Sequence[Tag]) -> None:
        """Tag database callback: remember what changed (encoding waits for a read)."""
        backlog = self._backlog
        backlog.extend(changed)
        if len(backlog) > self._backlog_limit:
            backlog.clear()
            self._stale = bytearray(b"\x01") * len(self._tags)

    def refresh(self, table: Table, first_word: int, count: int, target: list[int], target_offset: int) -> None:
        """Copy `count` current words of `table` from `first_word` into a pymodbus register block."""
        self._absorb_backlog()
        if table.is_bit:
            start, end = first_word * 16, (first_word + count) * 16
        else:
            start, end = first_word, first_word + count
        stale, tags, writers = self._stale, self._tags, self._writers
        for index in self.map.indices(table, start, end):
            if stale[index]:
                writers[index](tags[index].value)
                stale[index] = 0  # only once encoded: a value that fails to encode stays stale
        words = self.words[table][first_word : first_word + count]
        if len(words) != count:  # the request guard keeps reads inside the table; never shrink the block
            raise IndexError(f"{table.value} words {first_word}..{first_word + count - 1} are outside the image")
        target[target_offset : target_offset + count] = words

    def encode_all(self) -> None:
        """Bring every tag's words up to date (used by tests and tools, not on the hot path)."""
        self._absorb_backlog()
        for index, tag in enumerate(self._tags):
            self._writers[index](tag.value)
        self._stale = bytearray(len(self._tags))

    def _absorb_backlog(self) -> None:
        if not self._backlog:
            return
        backlog, self._backlog = self._backlog, []
        index_of, stale = self._index.get, self._stale
        for tag in backlog:
            index = index_of(tag)
            if index is not None:
                stale[index] = 1

    def _writer(self, mapping: Mapping) -> Writer:
        words = self.words[mapping.table]
        if mapping.codec is None:
            index, shift = divmod(mapping.address, 16)
            bit = 1 << shift

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
