"""Grouping a Modbus link's bound registers into as few requests as the protocol allows.

Reads: per table, bindings sorted by address join one request while the next starts at most
`gap` unbound registers after the previous one's end and the request stays within
`max_registers` (125 for FC3/FC4) or `max_bits` (2000 for FC1/FC2). With `gap: 0` (the default)
only contiguous registers are grouped, so no request ever touches a register nobody bound
(a strict device answers exception 02 for those).

Writes: the values of one batch, per table, in runs of adjacent addresses: one FC16 (at most
123 registers) or FC15 (at most 1968 coils) per run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from softplc.adapters.links.settings import TABLES, Binding

MAX_WRITE_REGISTERS = 123  # FC16
MAX_WRITE_COILS = 1968  # FC15


@dataclass(frozen=True)
class ReadGroup:
    """One read request: `count` registers (or bits) of `table` from `start`, and the bindings inside."""

    table: str
    start: int
    count: int
    bindings: tuple[Binding, ...]

    @property
    def end(self) -> int:
        return self.start + self.count

    def describe(self) -> str:
        return f"{self.table} {self.start}..{self.end - 1}"


def read_groups(bindings: Sequence[Binding], *, max_registers: int = 125, max_bits: int = 2000, gap: int = 0) -> list[ReadGroup]:
    """The read requests covering `bindings` (see the module docstring)."""
    groups: list[ReadGroup] = []
    for table in TABLES:
        limit = max_bits if table in ("coil", "discrete_input") else max_registers
        members: list[Binding] = []
        start = end = 0
        for binding in sorted((b for b in bindings if b.table == table), key=lambda b: b.address):
            binding_end = binding.address + binding.size
            if members and binding.address - end <= gap and max(end, binding_end) - start <= limit:
                members.append(binding)
                end = max(end, binding_end)
                continue
            if members:
                groups.append(ReadGroup(table, start, end - start, tuple(members)))
            members, start, end = [binding], binding.address, binding_end
        if members:
            groups.append(ReadGroup(table, start, end - start, tuple(members)))
    return groups


@dataclass(frozen=True)
class WriteRun:
    """One write request: words (registers) or bits (coils) from `start`, and the items they carry."""

    table: str
    start: int
    values: tuple[Any, ...]  # register words, or booleans for coils
    items: tuple[int, ...]  # indexes into the batch written


def write_runs(batch: Sequence[tuple[Binding, list[Any]]]) -> list[WriteRun]:
    """Runs of adjacent addresses per table; `batch` holds each binding with its encoded words (or [bit])."""
    runs: list[WriteRun] = []
    for table, limit in (("holding", MAX_WRITE_REGISTERS), ("coil", MAX_WRITE_COILS)):
        order = sorted((index for index, (binding, _) in enumerate(batch) if binding.table == table), key=lambda i: batch[i][0].address)
        values: list[Any] = []
        items: list[int] = []
        start = end = 0
        for index in order:
            binding, encoded = batch[index]
            if items and binding.address == end and len(values) + len(encoded) <= limit:
                values.extend(encoded)
                items.append(index)
                end += len(encoded)
                continue
            if items:
                runs.append(WriteRun(table, start, tuple(values), tuple(items)))
            values, items, start, end = list(encoded), [index], binding.address, binding.address + len(encoded)
        if items:
            runs.append(WriteRun(table, start, tuple(values), tuple(items)))
    return runs
