"""A program instance in a task: the program object, its bindings, its state and its fault record.

States: RUNNING (scanned every cycle), FAULTED (its scan or setup raised, or it stalled), STOPPED
(disabled in the configuration, or stopped by an engineer). A fault applies the program's fault
reaction (`softplc/core/fault_reaction.py`) and, with `restart: {delay, max}`, restarts it later. Every
start but the plant's first is a **warm start**: `setup()` runs inside
`softplc.core.function_blocks.warm_start()`, so the edge detectors it creates do not see a signal that
stayed high across the restart as a new edge; `program.restarted` says so, and
`program.first_scan` is true in the first scan after any start.
"""

from __future__ import annotations

import contextlib
import enum
import math
import traceback
from typing import Any

from softplc.core.fault_reaction import NEVER, FaultReaction, RestartPolicy
from softplc.core.function_blocks import warm_start
from softplc.core.program import Direction, Program, program_log
from softplc.core.tagdb import Rule, TagDatabase, WriteRejected
from softplc.util.log_format import BRIEF_TRACEBACK


class ProgramState(enum.Enum):
    RUNNING = "RUNNING"
    FAULTED = "FAULTED"
    STOPPED = "STOPPED"


Binding = str | list[str]


class ProgramInstance:
    """A program object with its tag bindings, its state and its fault record."""

    def __init__(
        self,
        name: str,
        program: Program,
        bindings: dict[str, Binding],
        restart: RestartPolicy = NEVER,
        reaction: FaultReaction = FaultReaction(),
        *,
        reference: str = "",
        params: dict[str, Any] | None = None,
    ) -> None:
        self.name = name
        self.program = program
        self.bindings = bindings
        self.restart = restart
        self.reaction = reaction
        self.reference = reference  # `module:Class` as configured (for listings)
        self.params = dict(params or {})
        self.state = ProgramState.RUNNING
        self.error = ""
        self.faults = 0
        self.restarts = 0
        self.version = 1  # online changes applied to it, plus one
        self._retry_at = math.inf
        self._reaction_due = False
        variables = type(program).variables
        self.outputs = {var: tag for var, tag in bindings.items() if variables[var].direction.writes}
        # The bindings split once by kind (one tag, or a list of tags): a scan runs thousands of
        # times a second under a simulated clock, and asking each binding its kind every time
        # was a third of the scan's own time.
        self._single_inputs = [(var, tag) for var, tag in bindings.items() if isinstance(tag, str)]
        self._list_inputs = [(var, list(tags)) for var, tags in bindings.items() if not isinstance(tags, str)]
        self._outputs = [(var, binding, isinstance(binding, str)) for var, binding in self.outputs.items()]  # in order
        # The tags `initial` sets back: those of Output variables (InOuts are state, see fault_reaction).
        self.output_tags = [tag for var, binding in self.outputs.items() if variables[var].direction is Direction.OUTPUT
                            for tag in ([binding] if isinstance(binding, str) else binding)]
        # Optional variables left unbound read as None and are never written.
        for var in variables:
            if var not in bindings:
                setattr(program, var, None)

    @property
    def tag_names(self) -> list[str]:
        names: list[str] = []
        for binding in self.bindings.values():
            names.extend([binding] if isinstance(binding, str) else binding)
        return names

    def start(self, now: float = 0.0, *, warm: bool = False) -> None:
        """Run the program's setup (`warm`: a restart, see the module docstring); a setup that raises faults it."""
        program = self.program
        program.restarted = warm
        program.first_scan = True
        try:
            with warm_start() if warm else contextlib.nullcontext():
                program.setup()
        except (Exception, SystemExit) as error:  # sys.exit() in a program must not end the runtime
            self.fault(error, now)

    def fault(self, error: BaseException | str, now: float) -> None:
        self.state = ProgramState.FAULTED
        self.faults += 1
        self._reaction_due = True
        if isinstance(error, BaseException):
            frame = traceback.extract_tb(error.__traceback__)[-1:] if error.__traceback__ else []
            where = f" at {frame[0].filename}:{frame[0].lineno}" if frame else ""
            self.error = f"{type(error).__name__}: {error}{where}"
        else:
            self.error = error
        # Under the program's own logger; the traceback is shown with -v (softplc.util.log_format).
        program_log(self.name).error("program %s FAULTED: %s", self.name, self.error,
                                     exc_info=error if isinstance(error, BaseException) else None,
                                     extra={BRIEF_TRACEBACK: True})
        if self.restart.automatic and self.restarts < self.restart.max_restarts:
            self._retry_at = now + self.restart.delay
        else:
            self._retry_at = math.inf

    def reaction_values(self, tags: TagDatabase) -> dict[str, Any]:
        """The fault reaction's values once after each fault or stop (empty otherwise, or when it holds)."""
        if not self._reaction_due:
            return {}
        self._reaction_due = False
        return self.reaction.values(self.output_tags, tags)

    def reset(self, now: float = 0.0) -> None:
        """Clear a fault and start again, warm (an operator's reset, `programs.start`)."""
        self.restarts = 0
        self.state = ProgramState.RUNNING
        self.error = ""
        self._retry_at = math.inf
        self.start(now, warm=True)

    def stop(self) -> None:
        """Stop scanning it (an engineer's `programs.stop`): its outputs take the fault reaction."""
        self.state = ProgramState.STOPPED
        self._retry_at = math.inf
        self._reaction_due = True

    def restart_due(self, now: float) -> bool:
        """Whether a FAULTED program's restart delay has passed (see `maybe_restart`)."""
        # 1 µs of tolerance, as for timers: 0.11 + 0.1 > 0.21 in floating point would cost a cycle.
        return self.state is ProgramState.FAULTED and now >= self._retry_at - 1e-6

    def maybe_restart(self, now: float) -> None:
        if self.restart_due(now):
            self.restarts += 1
            program_log(self.name).warning("restarting program %s (restart %d of %d)", self.name, self.restarts, self.restart.max_restarts)
            self.state = ProgramState.RUNNING
            self._retry_at = math.inf
            self.start(now, warm=True)  # a setup that fails again waits the full delay before the next try

    def scan(self, image: dict[str, Any], db: TagDatabase, now: float) -> dict[str, Any]:
        """Run one scan against `image`; return the validated outputs (the fault reaction's if it faulted)."""
        program = self.program
        attributes = program.__dict__
        for var, tag in self._single_inputs:
            attributes[var] = image[tag]
        for var, tags in self._list_inputs:
            attributes[var] = [image[tag] for tag in tags]
        try:
            program.scan()
        except (Exception, SystemExit) as error:  # sys.exit() in a program must not end the runtime
            self.fault(error, now)
            return self.reaction_values(db)
        if program.first_scan:
            program.first_scan = False
        outputs: dict[str, Any] = {}
        try:
            for var, binding, single in self._outputs:
                value = attributes[var]
                if single:
                    old = image[binding]
                    if value != old or type(value) is not type(old):
                        outputs[binding] = db.validate(binding, value, role=None)
                    continue
                if not isinstance(value, list) or len(value) != len(binding):
                    raise WriteRejected(var, Rule.TYPE_MISMATCH, f"must stay a list of {len(binding)} values")
                for tag, item in zip(binding, value):
                    if item != image[tag] or type(item) is not type(image[tag]):
                        outputs[tag] = db.validate(tag, item, role=None)
        except WriteRejected as rejected:
            self.fault(f"wrote an invalid value: {rejected}", now)
            return self.reaction_values(db)
        return outputs

