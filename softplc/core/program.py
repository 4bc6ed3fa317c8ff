"""Scan programs: a Python class with a `scan()` method whose variables are bound to tags.

    class InputBufferFiller(Program):
        items = InOut("items in the buffer")
        level = Output("fill level, %")
        capacity = Input("buffer capacity")
        period = Param(2.0, "seconds per item")

        def scan(self) -> None:
            ...

`tagdb.yaml` binds each variable to a tag (or a list of tags), so one class serves r01, r02
and r03 with different bindings — the thesis's variable→tag map. Before each scan the runtime
loads every bound variable from the task's input image; after it, Output and InOut variables
whose value changed become the program's outputs, committed with the rest of the task's
outputs at the end of the cycle.
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass
from typing import Any, ClassVar

from softplc.core.clock import Clock
from softplc.core.plant_role import RoleHolder
from softplc.util.durations import parse_duration

_MISSING: Any = object()


class Direction(enum.Enum):
    INPUT = "input"
    OUTPUT = "output"
    INOUT = "inout"

    @property
    def writes(self) -> bool:
        return self is not Direction.INPUT


class Variable:
    """A program variable bound to a tag (or, when bound to a list, to several tags)."""

    direction: ClassVar[Direction]

    def __init__(self, description: str = "", *, optional: bool = False) -> None:
        self.description = description
        self.optional = optional
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name


class Input(Variable):
    """Read from its tag each scan; changes made by the program are not written back."""

    direction = Direction.INPUT


class Output(Variable):
    """Written to its tag at the end of the cycle when the program changed it."""

    direction = Direction.OUTPUT


class InOut(Variable):
    """Read each scan and written back when changed (IEC VAR_IN_OUT)."""

    direction = Direction.INOUT


class Param:
    """A constant set from `params:` in the configuration (not a tag)."""

    def __init__(self, default: Any = _MISSING, description: str = "", *, duration: bool = False) -> None:
        self.default = default
        self.description = description
        self.duration = duration
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @property
    def required(self) -> bool:
        return self.default is _MISSING

    def convert(self, value: Any) -> Any:
        """Check a configured value against the default's type; raise ValueError if wrong."""
        if self.duration:
            return parse_duration(value)
        if self.default is _MISSING or self.default is None:
            return value
        expected = type(self.default)
        if expected is float and isinstance(value, int) and not isinstance(value, bool):
            return float(value)
        if not isinstance(value, expected) or (expected is int and isinstance(value, bool)):
            raise ValueError(f"expected {expected.__name__}, got {type(value).__name__} {value!r}")
        return value


@dataclass(frozen=True)
class ProgramContext:
    """What the runtime hands a program when it creates it."""

    name: str
    clock: Clock
    params: dict[str, Any]
    plant_role: RoleHolder | None = None  # the plant's role in a redundant pair (softplc/core/plant_role.py)


def program_log(name: str) -> logging.Logger:
    """The logger of program instance NAME: its own lines, its faults and restarts."""
    return logging.getLogger(f"softplc.core.program.{name}")


class Program:
    """Base class of scan programs. Override `scan()`; optionally `setup()` and `carry_over()`."""

    variables: ClassVar[dict[str, Variable]] = {}
    params: ClassVar[dict[str, Param]] = {}
    # Set by the runtime: True during the first scan after a start or a restart; and whether the
    # last setup() was a restart (after a fault, by programs.start/restart, or an online change).
    first_scan: bool = True
    restarted: bool = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        variables: dict[str, Variable] = {}
        params: dict[str, Param] = {}
        for klass in reversed(cls.__mro__):
            for name, attribute in vars(klass).items():
                if isinstance(attribute, Variable):
                    variables[name] = attribute
                elif isinstance(attribute, Param):
                    params[name] = attribute
        cls.variables = variables
        cls.params = params

    def __init__(self, context: ProgramContext) -> None:
        self.name = context.name
        self.clock = context.clock
        self.log = program_log(context.name)
        self.plant_role = context.plant_role
        for name, param in self.params.items():
            setattr(self, name, context.params.get(name, param.default))

    @property
    def now(self) -> float:
        """Current runtime time in seconds (simulated time under `--sim`)."""
        return self.clock.now()

    @property
    def epoch(self) -> int:
        """The epoch of the plant's active term (0 for a runtime alone): stamp every command sent to a remote
        device with it, so the device can ignore an older active of a redundant pair (docs/redundancy.md)."""
        return self.plant_role.epoch if self.plant_role is not None else 0

    @property
    def driving(self) -> bool:
        """Whether this plant may drive outputs right now (always, alone; in a redundant pair, only while
        its active term holds). Ask it immediately before a command leaves the plant: a process frozen in
        the middle of a scan wakes up in that scan, past its term, while the standby drives (docs/redundancy.md)."""
        return self.plant_role is None or self.plant_role.is_active()

    def setup(self) -> None:
        """Called once before the first scan, and again after a restart."""

    def scan(self) -> None:
        """One scan: read the bound variables, compute, assign outputs."""
        raise NotImplementedError(f"{type(self).__name__} must define scan()")

    def carry_over(self, old: Program) -> list[str] | None:
        """Take over the state of `old`, the version this one replaces in an online change.

        Called at the scan boundary of the swap, after this instance's `setup()`, so it must be
        quick. The default carries every attribute both have under the same name and type (or
        that this one's setup() left None) — timers, edge detectors, counters, lists — except the
        bound variables (loaded each scan), the parameters (the new configuration's win) and the
        runtime's own, like a PLC's online change keeps each variable whose declaration did not
        change. Override it to convert state, or return [] to carry nothing. Returns the names
        carried (for the engineer's report), or None when an override does not say.
        """
        return carry_attributes(old, self)


_RUNTIME_ATTRIBUTES = frozenset({"name", "clock", "log", "first_scan", "restarted", "plant_role"})


def carry_attributes(old: Program, new: Program) -> list[str]:
    """Copy from `old` to `new` each attribute both have with the same type (see `Program.carry_over`)."""
    skip = _RUNTIME_ATTRIBUTES | set(type(new).variables) | set(type(new).params)
    mine = new.__dict__
    carried = []
    for name, value in old.__dict__.items():
        if name in skip or name not in mine:
            continue
        if mine[name] is None or type(mine[name]) is type(value):
            mine[name] = value
            carried.append(name)
    return carried
