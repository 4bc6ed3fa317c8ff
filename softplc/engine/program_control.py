"""Program control: list the programs with their states; start, stop or restart one while the plant runs.

    programs.list                      any role   every program: task, state, error, faults, version...
    programs.start   {program}         engineer   a STOPPED or FAULTED program starts (warm: setup() again)
    programs.stop    {program}         engineer   it stops scanning; its outputs take its fault reaction
    programs.restart {program}         engineer   setup() again (warm) and scan on, whatever its state

Commands run on the event loop, between two cycles: a start or stop takes effect at the next
cycle of the program's task. A setup() run by a command is watched for stalls like a scan. A
start or stop lasts until the runtime stops: the configuration's `enabled:` says how a program
starts. Starting a program refuses to make a second writer of a tag (see "One writer per
output" in docs/runtime.md), as the configuration check does.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

from softplc.core.clock import Clock
from softplc.core.commands import CommandRefused, Commands, Permission
from softplc.core.origin import Origin
from softplc.engine.program_instance import ProgramInstance, ProgramState
from softplc.engine.scan import Task
from softplc.util.suggest import did_you_mean


class _Runtime(Protocol):
    """What these commands use of `softplc.app.runtime.Runtime` (which imports this module)."""

    commands: Commands
    clock: Clock
    tasks: Sequence[Task]

    @property
    def shared_outputs(self) -> set[str]: ...

    def run_setup(self, task: Task, instance: ProgramInstance, setup: Callable[[], None]) -> None: ...

    def programs_changed(self) -> None: ...


def actions(instance: ProgramInstance) -> list[str]:
    """The commands that make sense for a program in its state (for the HMI's buttons)."""
    if instance.state is ProgramState.RUNNING:
        return ["stop", "restart"]
    if instance.state is ProgramState.FAULTED:
        return ["start", "stop", "restart"]
    return ["start", "restart"]


def describe(task: Task, instance: ProgramInstance) -> dict[str, Any]:
    """One program as `programs.list` shows it."""
    return {
        "name": instance.name,
        "task": task.name,
        "state": instance.state.value,
        "error": instance.error,
        "faults": instance.faults,
        "restarts": instance.restarts,
        "program": instance.reference,
        "params": instance.params,
        "bind": instance.bindings,
        "on_fault": instance.reaction.describe(),
        "restart": instance.restart.describe(),
        "version": instance.version,
        "actions": actions(instance),
    }


def register_program_commands(runtime: _Runtime) -> None:
    commands = runtime.commands

    def find(arguments: Mapping[str, Any]) -> tuple[Task, ProgramInstance]:
        name = arguments.get("program")
        if not isinstance(name, str) or not name:
            raise CommandRefused("give the program's name as 'program'")
        for task in runtime.tasks:
            for instance in task.programs:
                if instance.name == name:
                    return task, instance
        names = [i.name for t in runtime.tasks for i in t.programs]
        raise CommandRefused(f"no program '{name}'{did_you_mean(name, names)}; programs: {', '.join(names) or 'none'}")

    def listing(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        return [describe(task, instance) for task in runtime.tasks for instance in task.programs]

    def start(arguments: Mapping[str, Any], origin: Origin) -> str:
        task, instance = find(arguments)
        if instance.state is ProgramState.RUNNING:
            raise CommandRefused(f"program {instance.name} is already RUNNING (programs.restart runs its setup() again)")
        if instance.state is ProgramState.STOPPED:
            _check_single_writer(runtime, instance)
        now = runtime.clock.now()
        runtime.run_setup(task, instance, lambda: instance.reset(now))
        if instance.state is not ProgramState.RUNNING:
            raise CommandRefused(f"program {instance.name} did not start: its setup() failed: {instance.error}")
        return f"started program {instance.name} (warm start: setup() ran; scanned from the next cycle of task {task.name})"

    def stop(arguments: Mapping[str, Any], origin: Origin) -> str:
        task, instance = find(arguments)
        if instance.state is ProgramState.STOPPED:
            raise CommandRefused(f"program {instance.name} is already STOPPED")
        instance.stop()
        runtime.programs_changed()
        reaction = instance.reaction.describe()
        outputs = "its outputs hold their values" if reaction == "hold" else f"its outputs took its fault reaction ({reaction})"
        return f"stopped program {instance.name}: {outputs}"

    def restart(arguments: Mapping[str, Any], origin: Origin) -> str:
        task, instance = find(arguments)
        if instance.state is ProgramState.STOPPED:
            _check_single_writer(runtime, instance)
        now = runtime.clock.now()
        runtime.run_setup(task, instance, lambda: instance.reset(now))
        if instance.state is not ProgramState.RUNNING:
            raise CommandRefused(f"program {instance.name} did not restart: its setup() failed: {instance.error}")
        return f"restarted program {instance.name} (warm start: setup() ran again)"

    commands.register("programs.list", listing, permission=Permission.VIEW, description="list programs")
    program = {"program": "program name"}
    commands.register("programs.start", start, permission=Permission.ENGINEER, description="start programs", arguments=program)
    commands.register("programs.stop", stop, permission=Permission.ENGINEER, description="stop programs", arguments=program)
    commands.register("programs.restart", restart, permission=Permission.ENGINEER, description="restart programs", arguments=program)


def _check_single_writer(runtime: _Runtime, starting: ProgramInstance) -> None:
    """Refuse to start a program that would be a second writer of a tag (not declared shared_output)."""
    writers: dict[str, str] = {}
    for task in runtime.tasks:
        for instance in task.programs:
            if instance is starting or instance.state is ProgramState.STOPPED:
                continue
            for tag in _written(instance):
                writers.setdefault(tag, instance.name)
    clashes = [(tag, writers[tag]) for tag in _written(starting) if tag in writers and tag not in runtime.shared_outputs]
    if clashes:
        listed = ", ".join(f"'{tag}' (written by {other})" for tag, other in clashes)
        raise CommandRefused(f"starting program {starting.name} would make two programs write {listed} (the double-coil bug): "
                             "stop the other program first, or declare the tag shared_output: true")


def _written(instance: ProgramInstance) -> list[str]:
    return [tag for binding in instance.outputs.values() for tag in ([binding] if isinstance(binding, str) else binding)]
