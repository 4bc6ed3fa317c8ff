"""A plant's state captured at a cycle boundary by the active of a redundant pair, and applied by its standby.

The active calls `capture(task)` right after each cycle (`plant.after_cycle`): a `CycleState`
holding what changed since the previous capture — the tags that changed (the `_sys.` tags are
each runtime's own and never copied), the forces when they changed, the state of the task's
programs (their attributes, as online change carries them over, `program_state.py`; their
RUNNING/FAULTED/STOPPED record), the programs' time, the write journal's applied position, and
the adapters' registered parts (e.g. the alarms' states). `capture_full()` takes all of it, for a
standby that (re)connects. The standby `apply`s each state in order; a gap is refused.

Writes are acknowledged to clients when journaled, before the cycle that applies them: the
active hands every journal entry to the standby at once (`TagDatabase.on_journal`), the standby
`hold`s those not yet applied, and when it takes over, `take_over()` puts them back into its own
journal: a write acknowledged Good by the active is applied by whichever runtime runs next.

Nothing here knows how states travel; softplc/engine/replication_wire.py turns them into plain
lists and checks what comes back.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from softplc.core.clock import Clock, PlantTime
from softplc.core.forcing import Force, ForceChange
from softplc.core.tagdb import TagDatabase, Write
from softplc.core.tags import Quality, Tag
from softplc.engine.program_instance import ProgramInstance, ProgramState
from softplc.engine.program_state import ProgramStateError, apply_state, dump_state, load_state
from softplc.engine.scan import Task

log = logging.getLogger(__name__)

SYSTEM_PREFIX = "_sys."


class ReplicationError(Exception):
    """A state that cannot be applied (out of order, unknown names, a refused program state); nothing of it was applied."""


@dataclass
class ProgramImage:
    """One program's record and state at a boundary; `state` None when unchanged since the previous capture."""

    name: str
    status: str  # RUNNING, FAULTED or STOPPED
    error: str
    faults: int
    restarts: int
    version: int
    retry_in: float | None  # seconds until a FAULTED program's restart (None: none due)
    state: bytes | None


@dataclass
class CycleState:
    """What changed in a plant since the previous capture, at one cycle boundary (see the module docstring)."""

    sequence: int
    full: bool
    task: str  # the task whose cycle just ended ('' for a full capture)
    time: float  # the programs' clock at the boundary
    journal: int  # the write journal's applied position
    tags: list[tuple[str, Any, Quality, float]] = field(default_factory=list)
    forces: list[Force] | None = None  # None: unchanged
    programs: list[ProgramImage] = field(default_factory=list)
    parts: dict[str, Any] = field(default_factory=dict)


@dataclass
class Part:
    """An adapter's own state replicated with the plant's (`Plant.replicate`)."""

    capture: Callable[[bool], Any]  # (full) -> the part's plain state, None when unchanged
    check: Callable[[Any], Any]  # the plain state -> what `apply` takes; raises StateRefused
    apply: Callable[[Any], None]


class Replication:
    """Captures (active) and applies (standby) a plant's state; holds the journal a standby may have to resume."""

    def __init__(self, db: TagDatabase, tasks: Sequence[Task], program_clock: PlantTime, engine_clock: Clock,
                 parts: dict[str, Part] | None = None) -> None:
        """`parts`: the adapters' parts by name, shared with whoever registers them (the runtime)."""
        self.db = db
        self.tasks = tasks
        self.program_clock = program_clock
        self.engine_clock = engine_clock
        self.sequence = 0  # of the last capture (active) or the last state applied (standby)
        self.applied = 0  # states applied as a standby
        self.unpicklable: dict[str, str] = {}  # program → why its state cannot be captured
        self._changed: dict[str, Tag] = {}
        self._forces_seen = -1
        self._last_state: dict[str, bytes] = {}
        self._parts: dict[str, Part] = parts if parts is not None else {}
        self._held: list[tuple[int, Write | ForceChange]] = []  # journal entries of the active, not yet applied there
        self.journal_position: int | None = None  # the active's applied position in the last state applied
        self._applying = False
        db.on_change(self._note_changed)

    @property
    def programs(self) -> dict[str, ProgramInstance]:
        return {instance.name: instance for task in self.tasks for instance in task.programs}

    def add_part(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                 apply: Callable[[Any], None]) -> Callable[[], None]:
        """Replicate an adapter's own state too (`Plant.replicate`): capture on the active, check then apply on the standby."""
        part = Part(capture, check, apply)
        self._parts[name] = part
        return lambda: self._parts.pop(name, None) if self._parts.get(name) is part else None

    def _note_changed(self, tags: Sequence[Tag]) -> None:
        if self._applying:
            return
        changed = self._changed
        for tag in tags:
            if not tag.name.startswith(SYSTEM_PREFIX):
                changed[tag.name] = tag

    # -- the active -------------------------------------------------------------------------

    def capture(self, task: Task | None) -> CycleState:
        """What changed since the previous capture, at the end of `task`'s cycle (None: between cycles, a heartbeat)."""
        if task is None:
            return self._capture([], "", full=False)
        return self._capture(task.programs, task.name, full=False)

    def capture_full(self) -> CycleState:
        """Everything: every tag, the forces, every program, every part (for a standby that connects)."""
        for tag in self.db:
            if not tag.name.startswith(SYSTEM_PREFIX):
                self._changed[tag.name] = tag
        self._forces_seen = -1
        self._last_state.clear()
        return self._capture([instance for task in self.tasks for instance in task.programs], "", full=True)

    def _capture(self, instances: Sequence[ProgramInstance], task: str, *, full: bool) -> CycleState:
        self.sequence += 1
        db = self.db
        changed, self._changed = self._changed, {}
        state = CycleState(self.sequence, full, task, self.program_clock.now(), db.applied_position,
                           [(name, tag.value, tag.quality, tag.timestamp) for name, tag in changed.items()])
        forces = db.forces
        if forces.changes != self._forces_seen:
            self._forces_seen = forces.changes
            state.forces = forces.active()
        now = self.engine_clock.now()
        for instance in instances:
            state.programs.append(self._program_image(instance, now))
        for name, part in self._parts.items():
            captured = part.capture(full)
            if captured is not None:
                state.parts[name] = captured
        return state

    def _program_image(self, instance: ProgramInstance, now: float) -> ProgramImage:
        retry_at = instance._retry_at  # noqa: SLF001 - the engine's own record
        retry_in = retry_at - now if retry_at != float("inf") else None
        data: bytes | None = None
        try:
            data = dump_state(instance.program, self.program_clock)
            self.unpicklable.pop(instance.name, None)
        except ProgramStateError as error:
            if instance.name not in self.unpicklable:
                log.warning("program %s: its state cannot be copied to the standby (%s); a standby that takes over "
                            "starts it warm from its own setup()", instance.name, error)
            self.unpicklable[instance.name] = str(error)
        if data is not None and self._last_state.get(instance.name) == data:
            data = None  # unchanged: the standby has it
        elif data is not None:
            self._last_state[instance.name] = data
        return ProgramImage(instance.name, instance.state.value, instance.error, instance.faults, instance.restarts,
                            instance.version, retry_in, data)

    # -- the standby ------------------------------------------------------------------------

    def check(self, state: CycleState) -> None:
        """Raise ReplicationError unless `state` can be applied next (in order, known names)."""
        if not state.full and state.sequence != self.sequence + 1:
            raise ReplicationError(f"state {state.sequence} out of order: the last one applied here is {self.sequence}")
        programs = self.programs
        unknown = [image.name for image in state.programs if image.name not in programs]
        unknown += [name for name in state.parts if name not in self._parts]
        if unknown:
            raise ReplicationError(f"unknown program or part {', '.join(sorted(unknown))}")

    def apply(self, state: CycleState, packages: frozenset[str] | None = None) -> None:
        """Make this plant's state the active's at that boundary (a standby; see the module docstring)."""
        self.check(state)
        programs = self.programs
        packages = packages if packages is not None else self.program_packages()
        # Unpickled and checked first: a refused program state or part leaves everything as it was.
        loaded = {image.name: load_state(image.state, self.program_clock, packages) for image in state.programs
                  if image.state is not None}
        parts = {name: self._parts[name].check(part_state) for name, part_state in state.parts.items()}
        db = self.db
        if state.full:
            db.discard_journal()
        self._applying = True  # what the active changed is not this standby's own change to send anywhere
        try:
            db.mirror(state.tags)
        finally:
            self._applying = False
        if state.forces is not None:
            db.mirror_forces(state.forces)
        self.program_clock.align(state.time)
        now = self.engine_clock.now()
        for image in state.programs:
            instance = programs[image.name]
            if image.name in loaded:
                apply_state(instance.program, loaded[image.name])
            instance.state = ProgramState(image.status)
            instance.error, instance.faults, instance.restarts, instance.version = image.error, image.faults, image.restarts, image.version
            instance._retry_at = now + image.retry_in if image.retry_in is not None else float("inf")  # noqa: SLF001
            instance._reaction_due = False  # noqa: SLF001 - the active committed its reaction already
        for name, checked in parts.items():
            self._parts[name].apply(checked)
        self.sequence = state.sequence
        self.applied += 1
        self._changed.clear()
        self._held = [(position, entry) for position, entry in self._held if position >= state.journal]
        self.journal_position = state.journal

    def hold(self, position: int, entries: Sequence[Write | ForceChange | None]) -> None:
        """Keep the active's journal entries from `position` on until a state says they were applied there (None: a skipped place)."""
        self._held.extend((position + offset, entry) for offset, entry in enumerate(entries) if entry is not None)

    @property
    def held(self) -> int:
        return len(self._held)

    def take_over(self) -> int:
        """This standby becomes active: resume the active's journal where it stood; returns the writes resumed."""
        position = self.journal_position
        self.journal_position = None
        entries = [entry for at, entry in sorted(self._held, key=lambda item: item[0]) if position is not None and at >= position]
        self._held = []
        if position is not None:  # it mirrored an active: carry on with that one's journal
            self.db.resume_journal(position, entries)
        self._changed.clear()
        self._last_state.clear()
        self._forces_seen = -1
        return len(entries)

    def program_packages(self) -> frozenset[str]:
        """The top packages of the running programs' modules: their classes may appear in program states."""
        return frozenset(type(instance.program).__module__.split(".")[0] for instance in self.programs.values())
