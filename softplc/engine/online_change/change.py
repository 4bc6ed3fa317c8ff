"""Online change: a program's new code or settings swapped in at a scan boundary while the plant runs.

`programs.apply` (engineer; `softplc apply`, the HMI's button, any adapter) re-reads the file the
runtime was started with and checks it exactly as `softplc check` does, with every program
module compiled fresh from its source (`softplc/engine/online_change/fresh.py`). Off the scan path (a worker
thread on the real clock) it also creates and sets up (`setup()`, warm) the new version of every
changed program. If anything is wrong — a located problem in the file or a program, a setup()
that raises, a change that needs a restart (`softplc/engine/online_change/diff.py`) — nothing is applied and
the command is refused with the problems and the differences. Otherwise, between two cycles
(commands run on the event loop, which also runs the scan), each new version takes over the
state of the old one (`Program.carry_over`), and each task's program list is replaced: pointer
changes, so no task misses a cycle. `{"check": true}` checks and shows the differences only.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from softplc.config.loader import load_config
from softplc.config.plant import PlantConfig
from softplc.config.programs import raised_at, split_reference
from softplc.config.yamlsource import ConfigError
from softplc.core.clock import Clock, wait_for
from softplc.core.commands import CommandRefused, Commands, Permission
from softplc.core.function_blocks import warm_start
from softplc.core.origin import Origin
from softplc.core.plant_role import RoleHolder
from softplc.core.program import Program, ProgramContext
from softplc.engine.online_change.diff import ConfigDiff, diff_configs
from softplc.engine.online_change.fresh import FreshModules, module_file, source_digest
from softplc.engine.program_instance import ProgramInstance, ProgramState
from softplc.engine.scan import ScanEngine, Task
from softplc.engine.scan_gate import ScanGate
from softplc.util.plurals import plural
from softplc.util.realtime import shorten_switch_interval

log = logging.getLogger(__name__)

# While the check runs in its thread, the scan's thread must get the interpreter lock back
# quickly when a cycle is due: the switch interval is shortened (softplc/util/realtime.py, as for the
# stores' writer threads) and the check steps aside whenever a cycle is due (softplc/engine/scan_gate.py). bench/online_change.py
# --no-gate shows why: without it the 10 ms task's median start latency grows from ~0.01 to ~1-2.5 ms.
USE_SCAN_GATE = True
CHECK_TIMEOUT = 60.0  # a new version's setup() that never returns: the engineer is told, not left waiting


class _Runtime(Protocol):
    """What the online change uses of `softplc.app.runtime.Runtime` (which imports this module)."""

    config: PlantConfig
    clock: Clock
    program_clock: Clock  # what programs read (the runtime's clock, aligned with an active's in a standby)
    role: RoleHolder  # the plant's role (programs stamp remote commands with its epoch)
    commands: Commands
    engine: ScanEngine
    tasks: Sequence[Task]

    @property
    def scan_gate(self) -> ScanGate | None: ...

    @property
    def stopping(self) -> bool: ...

    def programs_changed(self) -> None: ...


class ChangeRefused(CommandRefused):
    """An online change that was not applied; `details` is what `{"check": true}` would have returned."""

    def __init__(self, message: str, details: dict[str, Any]) -> None:
        super().__init__(message)
        self.details = details


@dataclass
class Prepared:
    """A checked change, ready to swap: the new configuration and the new programs, set up."""

    config: PlantConfig | None = None
    diff: ConfigDiff = field(default_factory=ConfigDiff)
    problems: list[str] = field(default_factory=list)
    programs: dict[str, Program] = field(default_factory=dict)
    modules: FreshModules = field(default_factory=FreshModules)
    code: dict[str, str] = field(default_factory=dict)


class OnlineChange:
    """The online changes of one runtime, one at a time; registers `programs.apply`."""

    def __init__(self, runtime: _Runtime) -> None:
        self.runtime = runtime
        self.config = runtime.config  # what runs now
        self.code = _code_digests(runtime.config)  # each program's module source as it was loaded
        self.applied = 0
        self._busy: Origin | None = None
        self._step = ""  # what the check is doing (read from the loop if it takes too long)
        # The check runs in a worker thread on the real clock: it steps aside around every release.
        self._gate = runtime.scan_gate if USE_SCAN_GATE else None  # the runtime's one gate (None on a simulated clock)
        runtime.commands.register(
            "programs.apply", self._command, permission=Permission.ENGINEER, description="apply online changes",
            arguments={"check": "true: check the file and show the differences, apply nothing"},
        )

    async def _command(self, arguments: Mapping[str, Any], origin: Origin) -> dict[str, Any]:
        check = arguments.get("check", False)
        if isinstance(check, str):
            check = check.strip().lower() in ("true", "1", "yes", "on")
        return await self.apply(check=bool(check), origin=origin)

    async def apply(self, *, check: bool = False, origin: Origin | None = None) -> dict[str, Any]:
        """Check the file and (unless `check`) swap the change in; raise ChangeRefused if it cannot be applied."""
        if self._busy is not None:
            raise CommandRefused(f"an online change is already under way (asked by {self._busy}): try again when it is done")
        self._busy = origin or Origin("runtime", role=None)
        self._step = "reading the file"
        work = asyncio.ensure_future(self.runtime.clock.run_blocking(self._prepare))
        try:
            try:
                prepared = await wait_for(self.runtime.clock, asyncio.shield(work), CHECK_TIMEOUT)
            except TimeoutError:
                # The worker thread cannot be stopped: the next change waits until it has returned.
                work.add_done_callback(lambda _: setattr(self, "_busy", None))
                raise CommandRefused(f"the check has not finished after {CHECK_TIMEOUT:g} s ({self._step}): nothing applied; "
                                     "no other change can be applied until it returns") from None
            details = self._details(prepared)
            if prepared.problems:
                raise ChangeRefused(_refusal(plural(len(prepared.problems), "problem"), prepared.problems, prepared.diff), details)
            if prepared.diff.needs_restart:
                reasons = prepared.diff.needs_restart
                raise ChangeRefused(_refusal("changes that need a restart of the runtime", reasons, prepared.diff), details)
            if check or prepared.diff.empty:
                what = "nothing to apply: the running programs match the file" if prepared.diff.empty else "checked, not applied"
                return {**details, "summary": f"{what} ({self.config.path})"}
            if self.runtime.stopping:
                raise CommandRefused("the runtime is stopping: nothing applied")
            return {**details, **self._swap(prepared)}
        finally:
            if work.done():
                self._busy = None

    # -- off the scan path ------------------------------------------------------------------

    def _prepare(self) -> Prepared:
        """Check the file with fresh program modules and set up each changed program's new version."""
        prepared = Prepared()
        gate: contextlib.AbstractContextManager[Any] = contextlib.nullcontext()
        if not self.runtime.clock.simulated:
            shorten_switch_interval()
        if self._gate is not None:  # a worker thread: keep the interpreter lock free for the scan
            gate = self._gate.worker()
        with gate:
            return self._check(prepared)

    def _check(self, prepared: Prepared) -> Prepared:
        """The file checked with fresh modules, the differences, and the new versions set up (warm)."""
        self._step = f"checking {self.config.path} and importing its program modules"
        try:
            config = load_config(self.config.path, load_module=prepared.modules)
        except ConfigError as error:
            prepared.problems = [str(problem) for problem in error.problems]
            return prepared
        prepared.config = config
        prepared.code = _code_digests(config, prepared.modules)
        prepared.diff = diff_configs(self.config, config, self.code, prepared.code)
        if prepared.diff.needs_restart:
            return prepared
        programs = {program.name: program for task in config.tasks for program in task.programs}
        for change in prepared.diff.programs:
            if change.new_program:
                self._step = f"setup() of the new version of program {change.name}"
                self._new_version(prepared, programs[change.name])
        return prepared

    def _new_version(self, prepared: Prepared, program: Any) -> None:
        """Create and set up (warm) the new version of a program; a failure is one of the change's problems."""
        where = f"{program.location}: " if program.location is not None else ""
        try:
            with warm_start():
                created = program.cls(ProgramContext(program.name, self.runtime.program_clock, dict(program.params), self.runtime.role))
                created.restarted = True
                created.first_scan = True
                created.setup()
        except (Exception, SystemExit) as error:  # user code: report it, never a traceback
            prepared.problems.append(f"{where}the new version of program '{program.name}' cannot start: "
                                     f"{type(error).__name__}: {error}{raised_at(error)}")
            return
        prepared.programs[program.name] = created

    # -- at a scan boundary -----------------------------------------------------------------

    def _swap(self, prepared: Prepared) -> dict[str, Any]:
        """Carry the state over and replace the programs: synchronous, so no cycle runs in between."""
        config = prepared.config
        assert config is not None
        current = {instance.name: (task, instance) for task in self.runtime.tasks for instance in task.programs}
        config_of = {program.name: program for task in config.tasks for program in task.programs}
        changes = {change.name: change for change in prepared.diff.programs}
        carried: dict[str, list[str] | None] = {}
        for name, program in prepared.programs.items():  # user code first: if it raises, nothing is swapped
            try:
                carried[name] = program.carry_over(current[name][1].program)
            except Exception as error:
                problem = f"carry_over() of the new version of program '{name}' raises {type(error).__name__}: {error}{raised_at(error)}"
                raise ChangeRefused(_refusal("a problem", [problem], prepared.diff), self._details(prepared, [problem])) from None
        report = []
        for task_config in config.tasks:
            task = next(task for task in self.runtime.tasks if task.name == task_config.name)
            programs = []
            for program_config in task_config.programs:
                instance = current[program_config.name][1]
                change = changes.get(program_config.name)
                if change is not None:
                    instance = self._changed(instance, program_config, prepared.programs.get(change.name), change.started)
                    report.append({"name": instance.name, "task": task.name, "changes": change.changes, "state": instance.state.value,
                                   "new_program": change.new_program, "carried_over": carried.get(instance.name)})
                programs.append(instance)
            task.replace_programs(programs)
        self.runtime.programs_changed()  # of programs the change disabled
        prepared.modules.install({split_reference(config_of[name].reference)[0] for name in prepared.programs})
        self.config = config
        self.runtime.config = config
        self.code = prepared.code
        self.applied += 1
        names = ", ".join(entry["name"] for entry in report) or "program order"
        log.info("online change %d applied from %s: %s", self.applied, config.path, "; ".join(prepared.diff.lines()))
        return {"applied": True, "programs": report, "summary": f"online change {self.applied} applied: {names}"}

    @staticmethod
    def _changed(old: ProgramInstance, config: Any, program: Program | None, started: bool) -> ProgramInstance:
        """The instance that runs from now on: a new one around a new program, or the old one with new policies."""
        if program is None:  # on_fault, restart or enabled: false only
            old.reaction, old.restart = config.on_fault, config.restart
            old.version += 1
            if not config.enabled and old.state is not ProgramState.STOPPED:
                old.stop()
            return old
        new = ProgramInstance(config.name, program, config.bindings, config.restart, config.on_fault,
                              reference=config.reference, params=config.params)
        new.faults, new.version = old.faults, old.version + 1
        if not config.enabled:
            new.stop()
        elif old.state is ProgramState.STOPPED and not started:
            new.state = ProgramState.STOPPED  # stopped by an engineer: stays stopped with its new version
        return new

    def _details(self, prepared: Prepared, problems: list[str] | None = None) -> dict[str, Any]:
        return {
            "file": str(self.config.path),
            "applied": False,
            "changes": prepared.diff.lines(),
            "needs_restart": prepared.diff.needs_restart,
            "problems": problems if problems is not None else prepared.problems,
        }


def _code_digests(config: PlantConfig, fresh: FreshModules | None = None) -> dict[str, str]:
    """Each program's module source digest: from the fresh modules, or read now (the running ones)."""
    digests: dict[str, str] = {}
    for task in config.tasks:
        for program in task.programs:
            try:
                module, _ = split_reference(program.reference)
            except ImportError:
                continue
            if fresh is not None and module in fresh.digests:
                digests[program.name] = fresh.digests[module]
            else:
                digests[program.name] = source_digest(module_file(module, config.base_dir))
    return digests


def _refusal(what: str, reasons: list[str], diff: ConfigDiff) -> str:
    lines = [f"online change refused, nothing applied: {what}:", *(f"  {reason}" for reason in reasons)]
    other = [line for line in diff.lines() if not line.startswith("needs a restart: ")]
    if other:
        lines += ["the other differences (not applied):", *(f"  {line}" for line in other)]
    return "\n".join(lines)

