"""The `softplc` command line: a thin layer over the runtime and its adapters.

Core commands live here (run, check, tags, schema). Adapters add their own subcommands through
the modules their manifests list (`Manifest.commands`); the clients and the thesis tools through
the modules listed in COMMAND_MODULES. Each such module defines `add_commands(subparsers)` and
sets `func` on its parsers.
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import importlib
import json
import logging
import math
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from softplc import __version__
from softplc.app.console_status import print_task_statistics, status_loop
from softplc.config import PlantConfig, load_config
from softplc.config.sections import editor_schema
from softplc.config.yamlsource import ConfigError
from softplc.core.clock import RealClock, SimClock
from softplc.core.expression import Condition, ExpressionError
from softplc.util import logs
from softplc.util.console import print_table
from softplc.util.durations import format_duration
from softplc.util.plurals import plural
from softplc.util.realtime import cpu_list

if TYPE_CHECKING:
    from softplc.engine.retain import RetainError

EXIT_OK, EXIT_FAILURE, EXIT_CONFIG = 0, 1, 2
EXIT_RETAIN_CORRUPT = 3  # `softplc run`: retain.sqlite is corrupt; nothing started until the user chooses
DEFAULT_CONFIG = "tagdb.yaml"

# Modules of the clients and tools that add subcommands (each defines add_commands(subparsers));
# the adapters' come from their manifests.
COMMAND_MODULES: tuple[str, ...] = ("softplc.svm.cli", "softplc.scenarios.cli", "softplc.latency.cli", "softplc.clients.robot_agent.cli",
                                   "softplc.clients.alarms.cli", "softplc.clients.tags.cli", "softplc.clients.apply.cli", "softplc.clients.audit.cli")

log = logging.getLogger("softplc")


def main(argv: list[str] | None = None, *, process: bool = False) -> int:
    """Run one command; `process`: this is the `softplc` process itself (softplc/app/entry_point.py),
    which keeps ignoring stop signals after `run` until it exits, rather than restoring them."""
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        args.process = process
        try:
            logs.configure(logs.options_from_args(args))
        except logs.LogFileError as error:
            print(f"softplc: {error}", file=sys.stderr)
            return EXIT_FAILURE
        if not hasattr(args, "func"):
            parser.print_help()
            return EXIT_FAILURE
        return int(args.func(args) or 0)
    except ConfigError as error:
        _print_problems(error)
        return EXIT_CONFIG
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # e.g. `softplc tags | head`
        sys.stderr.close()
        return EXIT_OK
    finally:
        logs.flush_summaries()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="softplc",
        description="A PLC-style soft controller: tags, cyclic scan programs, OPC UA and Modbus TCP "
        "servers and mobile robots, configured in tagdb.yaml.",
        epilog="Start with: softplc check, then softplc run. Each command has --help.",
    )
    parser.add_argument("--version", action="version", version=f"softplc {__version__}")
    logs.add_log_arguments(parser)
    commands = parser.add_subparsers(title="commands", metavar="COMMAND")

    run = commands.add_parser(
        "run",
        help="run a plant: scan its programs and serve its tags",
        description="Load CONFIG, start the scan engine and the servers, and run until Ctrl-C, "
        "--duration or --until. Prints where it serves, a live status line, and per-task timing "
        "statistics on exit.",
        epilog="Examples: softplc run | softplc run --sim --duration 600 | "
        "softplc run --sim --until 't01_qSL >= 100 or t02_qSL >= 100'",
    )
    run.add_argument("config", nargs="?", default=DEFAULT_CONFIG, help=f"plant configuration (default {DEFAULT_CONFIG})")
    run.add_argument("--duration", type=_positive_number, metavar="S", help="stop after S seconds of scanning (runtime clock)")
    run.add_argument("--sim", action="store_true", help="simulated clock: as fast as possible, identical results every run "
                     "(starts from the initial values; retained values are neither restored nor saved)")
    run.add_argument("--speed", type=_positive_number, metavar="N", help="with --sim: run N times faster than real time")
    run.add_argument("--until", metavar="EXPR", help="stop when EXPR over tag names holds, e.g. 't01_qSL >= 100'")
    run.add_argument("--state-dir", type=Path, metavar="DIR", help="where retained values etc. are kept (default .softplc next to CONFIG)")
    run.add_argument("--no-status", action="store_true", help="no live status line")
    run.add_argument(
        "--corrupt-retain", choices=("refuse", "initial"), default="refuse",
        help="if STATE_DIR/retain.sqlite is corrupt: refuse to start (default, exit status 3), or set it aside "
        "(renamed retain.sqlite.corrupt-TIME) and start every retained tag from its initial value",
    )
    run.add_argument(
        "--loop", choices=("asyncio", "uvloop"), default="asyncio",
        help="event loop: asyncio (default) or uvloop (pip install uvloop; lower scan jitter)",
    )
    run.add_argument(
        "--rt-priority", type=int, metavar="N",
        help="run the scan loop under real-time scheduling (SCHED_FIFO, 1-99) so other processes "
        "cannot delay it; needs root or CAP_SYS_NICE",
    )
    run.add_argument(
        "--cpus", type=cpu_list, metavar="LIST",
        help="keep the runtime on these CPUs (e.g. 0, 0,2 or 2-3; Linux): a core of its own for the scan and its "
        "servers, clear of the clients and other processes you pin elsewhere",
    )
    from softplc.app.adapters import add_run_arguments

    add_run_arguments(run)
    run.set_defaults(func=cmd_run)

    check = commands.add_parser(
        "check",
        help="validate a configuration",
        description="Check CONFIG and every program it references. Exit 0 with a one-line summary, or "
        "exit 2 with FILE:LINE:COL: message for each problem.",
    )
    check.add_argument("config", nargs="?", default=DEFAULT_CONFIG)
    check.set_defaults(func=cmd_check)

    tags = commands.add_parser("tags", help="list the tags of a configuration", description="List every tag (templates expanded, system tags included).")
    tags.add_argument("config", nargs="?", default=DEFAULT_CONFIG)
    tags.add_argument("--format", choices=("table", "csv", "json"), default="table")
    tags.add_argument("--no-system", action="store_true", help="leave out the _sys. tags")
    tags.set_defaults(func=cmd_tags)

    schema = commands.add_parser("schema", help="print the JSON Schema of tagdb.yaml", description="Print the JSON Schema of the configuration file, for editors and CI.")
    schema.set_defaults(func=cmd_schema)

    from softplc.config.manifest import manifests

    for module_name in (*(name for manifest in manifests() for name in manifest.commands), *COMMAND_MODULES):
        importlib.import_module(module_name).add_commands(commands)
    logs.add_log_arguments_to_commands(parser)
    return parser


def _positive_number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, not {text}")
    return value


def _print_problems(error: ConfigError, stream: TextIO | None = None) -> None:
    stream = stream or sys.stderr  # looked up at call time, so redirections are honoured
    for problem in error.problems:
        print(problem, file=stream)
    count = len(error.problems)
    print(f"{plural(count, 'problem')} found", file=stream)


# -- check / tags / schema ------------------------------------------------------------------


def cmd_check(args: argparse.Namespace) -> int:
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import Runtime

    config = load_config(args.config)
    # Building (not starting) the runtime creates every program instance, and building the
    # adapters checks what only they know: the Modbus address map, OPC UA security settings,
    # the fleet's robots, tasks and map files.
    Runtime(config, SimClock())
    build_adapters(config, None)
    print(f"{args.config}: OK — {summary(config)}")
    return EXIT_OK


def summary(config: PlantConfig) -> str:
    tasks = ", ".join(f"{task.name} {format_duration(task.interval)}" for task in config.tasks) or "none"
    return f"{plural(len(config.tags), 'tag')}, {plural(len(config.tasks), 'task')} ({tasks}), {plural(config.program_count, 'program')}"


def cmd_schema(args: argparse.Namespace) -> int:
    print(json.dumps(editor_schema(), indent=2))
    return EXIT_OK


def cmd_tags(args: argparse.Namespace) -> int:
    from softplc.config.system_tags import runtime_tag_definitions

    config = load_config(args.config)
    definitions = list(config.tags)
    if not args.no_system:
        definitions += runtime_tag_definitions(config)
    rows = [
        {
            "name": d.name,
            "type": d.type.value,
            "initial": d.initial,
            "unit": d.unit,
            "access": d.access.value,
            "min": d.min,
            "max": d.max,
            "retain": d.retain,
            "group": d.group,
            "description": d.description,
        }
        for d in definitions
    ]
    if args.format == "json":
        print(json.dumps(rows, indent=2))
    elif args.format == "csv":
        writer = csv.DictWriter(sys.stdout, fieldnames=list(rows[0]) if rows else ["name"])
        writer.writeheader()
        writer.writerows(rows)
    else:
        columns = ("name", "type", "initial", "unit", "access", "min", "max", "retain", "group", "description")
        cells = [{**row, "retain": "yes" if row["retain"] else None} for row in rows]
        print_table([[("" if cell[c] is None else str(cell[c])) for c in columns] for cell in cells], columns)
    return EXIT_OK


# -- run ------------------------------------------------------------------------------------


def cmd_run(args: argparse.Namespace) -> int:
    from softplc.app.adapters import build_adapters
    from softplc.app.runtime import AdapterError, Runtime
    from softplc.app.stop_signals import StopSignals
    from softplc.app.stop_signals import describe as describe_signal
    from softplc.engine.retain import RetainError

    config = load_config(args.config)
    if args.speed is not None and not args.sim:
        print("softplc: --speed needs --sim (real time always runs at speed 1)", file=sys.stderr)
        return EXIT_FAILURE
    until = None
    runtime_probe_names = [d.name for d in config.tags]
    if args.until:
        from softplc.config.system_tags import runtime_tag_definitions

        try:
            until = Condition(args.until, runtime_probe_names + [d.name for d in runtime_tag_definitions(config)])
        except ExpressionError as error:
            print(f"softplc: --until: {error}", file=sys.stderr)
            return EXIT_CONFIG
    loop_factory = None
    if args.loop == "uvloop":
        try:
            import uvloop
        except ImportError:
            print("softplc: --loop uvloop needs the uvloop package: pip install uvloop", file=sys.stderr)
            return EXIT_FAILURE
        loop_factory = uvloop.new_event_loop
    from softplc.util.realtime import RealtimeError, set_cpu_affinity, set_realtime_priority

    for option, value, apply in (("--cpus", args.cpus, set_cpu_affinity), ("--rt-priority", args.rt_priority, set_realtime_priority)):
        if value is not None:
            try:
                apply(value)
            except RealtimeError as error:
                print(f"softplc: {option}: {error}", file=sys.stderr)
                return EXIT_FAILURE
    clock = SimClock(speed=args.speed) if args.sim else RealClock()
    logs.use_clock(clock)  # log timestamps in simulated time under --sim
    # A simulated run starts from the initial values and leaves the retained ones alone, so
    # it gives the same result every time and never disturbs the real plant's state.
    runtime = Runtime(config, clock, state_dir=args.state_dir, retain=not args.sim, corrupt_retain=args.corrupt_retain)
    for adapter in build_adapters(config, args):
        runtime.add_adapter(adapter)
    show_status = not args.no_status and sys.stderr.isatty()

    def stop_requested(signum: int) -> None:
        reason = describe_signal(signum)
        after_status_line = "\n" if show_status else ""
        print(f"{after_status_line}softplc: {reason}: stopping (the servers, then retained values are saved)", file=sys.stderr)
        runtime.request_stop(reason)

    def signal_again(signum: int) -> None:
        print(f"softplc: {signal.Signals(signum).name} received while stopping: ignored, the shutdown under way "
              "finishes first (SIGKILL abandons it)", file=sys.stderr)

    signals = StopSignals(stop_requested, signal_again)

    async def main_async() -> str:
        loop = asyncio.get_running_loop()
        if args.rt_priority is not None:
            from softplc.util.realtime import use_normal_priority_executor

            use_normal_priority_executor(loop)
        signals.attach(loop)  # a signal that came before (e.g. while the loop was created) stops the run now
        status = asyncio.create_task(status_loop(runtime, show_status, args))
        try:
            return await runtime.run(duration=args.duration, until=until)
        finally:
            status.cancel()
            signals.detach()

    mode = "simulated clock" + (f" x{args.speed:g}" if args.speed else ", as fast as possible") if args.sim else "real time"
    mode += f", {args.loop} event loop"
    print(f"softplc {__version__}: plant '{config.name}' — {summary(config)}; {mode}", file=sys.stderr)
    started = time.monotonic()
    # From here to the end, SIGINT and SIGTERM only ask for a stop (the first) or are ignored
    # (the others), never raised or fatal half-way through creating the loop, stopping the
    # servers, saving retained values or printing the statistics.
    signals.install()
    try:
        try:
            with asyncio.Runner(loop_factory=loop_factory) as runner:
                reason = runner.run(main_async())
        except AdapterError as error:
            print(f"softplc: cannot start: {error}", file=sys.stderr)
            return EXIT_FAILURE
        except RetainError as error:
            return _retain_refused(error)
        if show_status:
            print(file=sys.stderr)
        wall = time.monotonic() - started
        scanned = runtime.clock.now() - (runtime.started_at if runtime.started_at is not None else runtime.clock.now())
        clock_name = "simulated" if args.sim else "real"
        print(f"stopped: {reason or 'stopped'} — scanned {scanned:.1f} s of {clock_name} time; {wall:.1f} s wall time with start-up", file=sys.stderr)
        print_task_statistics(runtime, sys.stderr)
        if args.sim:
            print("(simulated clock: a scan takes no simulated time, so scan and latency times are 0 by construction)", file=sys.stderr)
        if runtime.error:
            print(f"softplc: the runtime was in ERROR when it stopped: {runtime.error}", file=sys.stderr)
        # A stop asked for by a signal (an operator, systemd) that went cleanly is a success
        # whatever happened before; a run that ended by itself reports an ERROR never reset.
        if signals.first is not None and reason == describe_signal(signals.first):
            return EXIT_OK
        return EXIT_OK if runtime.error == "" else EXIT_FAILURE
    finally:
        if not getattr(args, "process", False):  # called in-process (tests): give the caller its handlers back
            signals.restore()


def _retain_refused(error: RetainError) -> int:
    """Say why the retained values cannot be used and what the user may do; nothing has started."""
    print(f"softplc: cannot start: the retained values in {error.path} cannot be used: {error.detail}", file=sys.stderr)
    if not error.corrupt:
        return EXIT_FAILURE
    print(
        "softplc: nothing was started and the file was left as it is. Restore it from a backup, or start every "
        "retained tag from its initial value: run again with --corrupt-retain initial (the bad file is then kept "
        f"beside it as {error.path.name}.corrupt-TIME)",
        file=sys.stderr,
    )
    return EXIT_RETAIN_CORRUPT


if __name__ == "__main__":
    sys.exit(main())
