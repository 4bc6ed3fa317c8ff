"""Logging setup for every softplc command: levels, text or JSON lines, a rotating log file, flood limits.

    softplc run --log-file /var/log/softplc/plant.log --log-max-size 20MB --log-backups 10 --log-format json

- every line has a UTC timestamp (the runtime clock's under `--sim`: `use_clock`), its level and
  its logger (`softplc.core.program.NAME` for a program's own lines and its faults);
- `-v` shows debug lines and the tracebacks of program faults, `-vv` also asyncua's and
  pymodbus's debug lines; `-q` only warnings and errors;
- `--log-file PATH` writes the log there, rotated at `--log-max-size` into `--log-backups` old
  files (PATH.1 … PATH.N); the console (stderr) then gets only warnings and errors;
- every handler rate-limits lines per kind (`softplc.util.log_limit`), so no client can flood the log.

The options are accepted before the command (`softplc -v run`) and after it (`softplc run -v`).
"""

from __future__ import annotations

import argparse
import logging
import logging.handlers
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TextIO

from softplc.util.log_format import JsonFormatter, PlantTime, TextFormatter
from softplc.util.log_limit import DEFAULT_BURST, DEFAULT_INTERVAL, DEFAULT_LOGGER_BURST, FloodFilter

LOG_FORMATS = ("text", "json")
DEFAULT_MAX_BYTES = 10 * 1024 * 1024
DEFAULT_BACKUPS = 5
NOISY_LIBRARIES = ("asyncua", "pymodbus")  # their debug lines only with -vv
_SIZE = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([kmg]?)i?b?\s*$", re.IGNORECASE)
_SIZE_FACTORS = {"": 1, "k": 1024, "m": 1024**2, "g": 1024**3}


class LogFileError(Exception):
    """The log file cannot be opened; the message says which and why."""


@dataclass(frozen=True)
class LogOptions:
    """What the command line asked of the log."""

    verbosity: int = 0  # -v minus -q
    format: str = "text"
    file: Path | None = None
    max_bytes: int = DEFAULT_MAX_BYTES
    backups: int = DEFAULT_BACKUPS
    burst: int = DEFAULT_BURST  # lines of one kind per interval (softplc.util.log_limit)
    logger_burst: int = DEFAULT_LOGGER_BURST  # lines of one logger per interval
    interval: float = DEFAULT_INTERVAL


def parse_size(text: str) -> int:
    """An argparse type: a byte count such as 10MB, 512k, 1048576 (at least 1 KB)."""
    match = _SIZE.match(text)
    if match is None:
        raise argparse.ArgumentTypeError(f"{text!r} is not a size; write e.g. 10MB, 512KB or 1048576")
    size = int(float(match.group(1)) * _SIZE_FACTORS[match.group(2).lower()])
    if size < 1024:
        raise argparse.ArgumentTypeError(f"{text} is too small for a log file: at least 1KB")
    return size


def _backups(text: str) -> int:
    if not text.isdigit():
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of files (0 or more)")
    return int(text)


def add_log_arguments(parser: argparse.ArgumentParser, *, on_command: bool = False) -> None:
    """Add -v/-q/--log-* to `parser`; `on_command`: a subcommand's copy, which overrides only what it is given."""
    # A subcommand's defaults must not overwrite what was given before the command (`softplc -v run`).
    default: Callable[[Any], Any] = (lambda value: argparse.SUPPRESS) if on_command else (lambda value: value)
    group = parser.add_argument_group("logging")
    group.add_argument("-v", "--verbose", action="count", default=default(0),
                       help="more log output: debug lines and program-fault tracebacks (-vv: also asyncua's and pymodbus's)")
    group.add_argument("-q", "--quiet", action="count", default=default(0), help="less log output: warnings and errors only")
    group.add_argument("--log-format", choices=LOG_FORMATS, default=default("text"),
                       help="text (default) or json: one JSON object per line (time, level, logger, message, exception)")
    group.add_argument("--log-file", type=Path, metavar="PATH", default=default(None),
                       help="write the log to PATH, rotated by size (the console then shows warnings and errors only)")
    group.add_argument("--log-max-size", type=parse_size, metavar="SIZE", default=default(DEFAULT_MAX_BYTES),
                       help="rotate the log file at this size (default 10MB; e.g. 512KB, 1GB)")
    group.add_argument("--log-backups", type=_backups, metavar="N", default=default(DEFAULT_BACKUPS),
                       help=f"old log files to keep: PATH.1 … PATH.N (default {DEFAULT_BACKUPS})")


def add_log_arguments_to_commands(parser: argparse.ArgumentParser) -> None:
    """Give every subcommand (and sub-subcommand) of `parser` the logging options too."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for command in set(action.choices.values()):
                if "--log-file" not in command._option_string_actions:
                    add_log_arguments(command, on_command=True)
                add_log_arguments_to_commands(command)


def options_from_args(args: argparse.Namespace) -> LogOptions:
    return LogOptions(
        verbosity=getattr(args, "verbose", 0) - getattr(args, "quiet", 0),
        format=getattr(args, "log_format", "text"),
        file=getattr(args, "log_file", None),
        max_bytes=getattr(args, "log_max_size", DEFAULT_MAX_BYTES),
        backups=getattr(args, "log_backups", DEFAULT_BACKUPS),
    )


class _Setup:
    """What `configure` installed, so the clock and the flood summaries can reach it later."""

    def __init__(self) -> None:
        self.time = PlantTime()
        self.floods: list[FloodFilter] = []


_setup = _Setup()


class _Stderr(logging.StreamHandler):  # type: ignore[type-arg]
    """The console: whatever `sys.stderr` is when a line is written (a redirection, a test's capture)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property  # type: ignore[override]
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass


def configure(options: LogOptions = LogOptions(), stream: TextIO | None = None) -> None:
    """Replace the root logger's handlers with softplc's; raises LogFileError if the log file cannot be opened."""
    global _setup
    flush_summaries()
    level = logging.WARNING if options.verbosity < 0 else logging.INFO if options.verbosity == 0 else logging.DEBUG
    setup = _Setup()
    handlers: list[logging.Handler] = []
    if options.file is not None:
        try:
            options.file.parent.mkdir(parents=True, exist_ok=True)
            handlers.append(logging.handlers.RotatingFileHandler(
                options.file, maxBytes=options.max_bytes, backupCount=options.backups, encoding="utf-8",
            ))
        except OSError as error:
            raise LogFileError(f"--log-file {options.file}: {error.strerror or error}") from None
    console = logging.StreamHandler(stream) if stream is not None else _Stderr()
    if options.file is not None:
        console.setLevel(max(level, logging.WARNING))
    handlers.append(console)
    formatter = JsonFormatter() if options.format == "json" else TextFormatter(verbose=options.verbosity > 0)
    for handler in handlers:
        handler.setFormatter(formatter)
        flood = FloodFilter(handler.handle, burst=options.burst, logger_burst=options.logger_burst, interval=options.interval,
                            unlimited_below=logging.INFO if options.verbosity >= 2 else logging.NOTSET)
        handler.addFilter(flood)
        handler.addFilter(setup.time)
        setup.floods.append(flood)
    root = logging.getLogger()
    for old in root.handlers[:]:
        root.removeHandler(old)
        if old not in handlers and isinstance(old, logging.FileHandler):
            old.close()
    for handler in handlers:
        root.addHandler(handler)
    root.setLevel(level)
    for name in NOISY_LIBRARIES:
        logging.getLogger(name).setLevel(logging.NOTSET if options.verbosity >= 2 else logging.WARNING)
    _setup = setup


class _Clock(Protocol):
    """What logging reads of the runtime's clock (softplc.core.clock.Clock)."""

    @property
    def simulated(self) -> bool: ...

    def wall(self) -> float: ...


def use_clock(clock: _Clock | None) -> None:
    """Take log timestamps from `clock` if it is simulated (its wall time); real time otherwise."""
    _setup.time.source = clock.wall if clock is not None and clock.simulated else None


def flush_summaries() -> None:
    """Write the summary lines of every flood window still open (at exit, so no count is lost)."""
    for flood in _setup.floods:
        flood.close_windows(float("inf"))
