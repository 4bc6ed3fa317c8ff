"""A check shared by the list-bound programs: every per-task (or per-robot) list is as long as the others."""

from __future__ import annotations

from softplc import Program


def check_lengths(program: Program, *names: str) -> int:
    """The common length of the named list variables; ValueError naming the odd one out."""
    lengths = {name: len(getattr(program, name)) for name in names if getattr(program, name) is not None}
    expected = lengths[names[0]]
    for name, length in lengths.items():
        if length != expected:
            raise ValueError(f"'{name}' is bound to {length} tag{'' if length == 1 else 's'} but '{names[0]}' to {expected}: "
                             "bind one tag per task (or per robot) to each, in the same order")
    return expected
