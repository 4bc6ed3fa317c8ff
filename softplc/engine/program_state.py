"""A program's state as bytes, for a standby runtime: what online change carries over, across a link.

Online change hands a new program object the attributes of the old one (`Program.carry_over`).
A standby of a redundant pair needs the same attributes, but from another process: they are
pickled here at the active's cycle boundary and unpickled into the standby's program object.
The same attributes are carried as online change carries: everything but the bound variables
(loaded from the image each scan), the parameters (the configuration's) and the runtime's own.

The programs' clock is not sent: every reference to it (a timer's) is a persistent reference
that the standby resolves to its own program clock, which it keeps aligned with the active's.

Unpickling runs code named in the data, so it is restricted: only classes (never functions) of
the program modules' packages, of softplc, of numpy and scikit-learn, and the standard library's
containers and value types are found; anything else is refused (`ProgramStateError`). The bytes
only ever come over the pair's mutually authenticated sync link (docs/redundancy.md).
"""

from __future__ import annotations

import builtins
import io
import pickle
from typing import Any

from softplc.core.program import Program

SKIPPED = frozenset({"name", "clock", "log", "plant_role"})
CLOCK_ID = "softplc.clock"

_SAFE_BUILTINS = frozenset({
    "list", "dict", "set", "frozenset", "tuple", "bytearray", "bytes", "complex", "float", "int", "str",
    "bool", "slice", "range", "object", "NotImplemented", "Ellipsis",
})
_SAFE_MODULES = ("collections", "datetime", "decimal", "fractions", "random", "enum", "uuid", "ipaddress", "array")
_ROOTS = ("softplc", "numpy", "sklearn", "scipy")
_SAFE_FUNCTIONS = frozenset({
    ("copyreg", "_reconstructor"),
    ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
    ("numpy", "dtype"), ("_codecs", "encode"),
})


class ProgramStateError(Exception):
    """A program's state that cannot be pickled here, or that is refused when unpickled there."""


def state_attributes(program: Program) -> dict[str, Any]:
    """The attributes of `program` that are its state (see the module docstring)."""
    cls = type(program)
    skip = SKIPPED | set(cls.variables) | set(cls.params)
    return {name: value for name, value in program.__dict__.items() if name not in skip}


class _StatePickler(pickle.Pickler):
    def __init__(self, file: io.BytesIO, clock: object) -> None:
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self._clock = clock

    def persistent_id(self, obj: Any) -> str | None:  # noqa: D102 - pickle's hook
        return CLOCK_ID if obj is self._clock else None


def dump_state(program: Program, clock: object) -> bytes:
    """The program's state as bytes; raises ProgramStateError when an attribute cannot be pickled."""
    buffer = io.BytesIO()
    try:
        _StatePickler(buffer, clock).dump(state_attributes(program))
    except Exception as error:  # any attribute pickle cannot take (a lock, a generator, a socket)
        raise ProgramStateError(f"{type(error).__name__}: {error}") from None
    return buffer.getvalue()


class _StateUnpickler(pickle.Unpickler):
    def __init__(self, file: io.BytesIO, clock: object, packages: frozenset[str]) -> None:
        super().__init__(file)
        self._clock = clock
        self._packages = packages

    def persistent_load(self, pid: Any) -> Any:  # noqa: D102 - pickle's hook
        if pid == CLOCK_ID:
            return self._clock
        raise pickle.UnpicklingError(f"unknown persistent reference {pid!r}")

    def find_class(self, module: str, name: str) -> Any:  # noqa: D102 - pickle's hook
        if module == "builtins":
            if name in _SAFE_BUILTINS:
                return getattr(builtins, name)
            raise pickle.UnpicklingError(f"builtins.{name} is not allowed in a program's state")
        if (module, name) in _SAFE_FUNCTIONS:
            return super().find_class(module, name)
        root = module.split(".")[0]
        if module in _SAFE_MODULES or root in _ROOTS or root in self._packages or module in self._packages:
            found = super().find_class(module, name)
            if isinstance(found, type):
                return found
            raise pickle.UnpicklingError(f"{module}.{name} is not a class: not allowed in a program's state")
        raise pickle.UnpicklingError(f"{module}.{name} is not allowed in a program's state")


def load_state(data: bytes, clock: object, packages: frozenset[str]) -> dict[str, Any]:
    """The attributes pickled by `dump_state`; `packages`: the program modules' top packages. Raises ProgramStateError."""
    try:
        loaded = _StateUnpickler(io.BytesIO(data), clock, packages).load()
    except Exception as error:
        raise ProgramStateError(f"{type(error).__name__}: {error}") from None
    if not isinstance(loaded, dict) or not all(isinstance(key, str) for key in loaded):
        raise ProgramStateError("not a mapping of attribute names")
    return loaded


def apply_state(program: Program, attributes: dict[str, Any]) -> None:
    """Give `program` these state attributes (the skipped ones stay the program's own)."""
    skip = SKIPPED | set(type(program).variables) | set(type(program).params)
    for name, value in attributes.items():
        if name not in skip:
            program.__dict__[name] = value
