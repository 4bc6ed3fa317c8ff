"""The `softplc` command as a process (the console script; `python -m softplc` too).

Two things only a process needs, kept out of `cli.main` (which tests also call in-process):
- A Ctrl-C before the command has taken over the stop signals (Python still importing the
  command line, a configuration being loaded) exits with 130 and no traceback. The package's
  `__init__` loads its public names lazily and this module imports nothing at first, so the
  command's whole start is covered; only Python's own start-up (and the first line of the
  script pip writes, before it calls `main`) is left to Python.
- Once the command has returned its exit status, SIGINT and SIGTERM are ignored: the
  interpreter may still take a moment to exit (threads joined, files closed), and a second
  signal then must not turn a clean stop into death by that signal (exit status -2 or -15).
- Once the command is done and no other thread is left, the process ends without tearing the
  interpreter down: the exit handlers run and the output is flushed, but the millions of objects
  of a run (OPC UA address space, maps, robots) are left to the kernel, not freed one by one —
  that took 0.35-0.5 s after every `softplc run`, a sixth of a simulated ten minutes.
"""

from __future__ import annotations

EXIT_INTERRUPTED = 130  # 128 + SIGINT, what shells report for a Ctrl-C


def main() -> int:
    """Run the command line of `sys.argv` and return its exit status."""
    try:
        from softplc.app import cli

        status = cli.main(process=True)
    except KeyboardInterrupt:
        status = EXIT_INTERRUPTED
    status = _exiting(status)
    _leave_now(status)
    return status


def _exiting(status: int) -> int:
    import signal  # here: the less this module imports, the sooner main() is there to answer a Ctrl-C

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)
    return status


def _leave_now(status: int) -> None:
    """End the process at once when nothing else runs: exit handlers, flushed output, no teardown."""
    import atexit
    import os
    import sys
    import threading

    if threading.active_count() > 1:
        return  # a thread still working is joined by the ordinary exit, as Python does
    if sys.getprofile() is not None or sys.gettrace() is not None:
        return  # under a profiler or a debugger (python -m cProfile -m softplc ...): it reports at exit
    atexit._run_exitfuncs()  # logging's shutdown and any library's handlers, as at a normal exit
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be said there
            pass
    os._exit(status)
