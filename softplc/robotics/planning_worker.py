"""The planning worker process: `python -m softplc.robotics.planning_worker`, started by `ProcessPlanning`.

It reads frames from stdin and answers on stdout, one at a time, in order. A frame is a 4-byte
big-endian length and a pickle of `(kind, ident, body)`:

    ("planners", ident, [PathPlanner, ...])  → the worker's pid (the planners are kept)
    ("plan", ident, (index, serial, start, goal, discs, keep_out, detour, make_way)) → a Plan

and the answer is a pickle of `(ident, ok, value)`, where a failed request carries the error's
text. The worker ends when stdin closes (its runtime stopped or died).
"""

from __future__ import annotations

import signal

# Ctrl-C at a terminal reaches the whole process group: the runtime handles it and ends the
# worker by closing its stdin. Ignored first thing, before the (slow) imports below.
signal.signal(signal.SIGINT, signal.SIG_IGN)

import os  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
from typing import Any, BinaryIO  # noqa: E402

from softplc.robotics.driver import PlanRequest, run_plan  # noqa: E402
from softplc.robotics.planner import PathPlanner  # noqa: E402
from softplc.robotics.planning import HEADER, frame  # noqa: E402


def read_frame(stream: BinaryIO) -> Any | None:
    """The next frame's object, or None at the end of the stream."""
    header = stream.read(HEADER.size)
    if len(header) < HEADER.size:
        return None
    (size,) = HEADER.unpack(header)
    payload = stream.read(size)
    if len(payload) < size:
        return None
    return pickle.loads(payload)


def serve(requests: BinaryIO, replies: BinaryIO) -> None:
    planners: list[PathPlanner] = []
    while (message := read_frame(requests)) is not None:
        kind, ident, body = message
        try:
            if kind == "planners":
                planners = body
                value: Any = os.getpid()
            elif kind == "plan":
                index, serial, start, goal, discs, keep_out, detour, make_way = body
                value = run_plan(PlanRequest(serial, planners[index], start, goal, discs, keep_out, detour, make_way))
            else:
                raise ValueError(f"unknown request {kind!r}")
            reply = (ident, True, value)
        except Exception as error:  # a failed plan is the robot's problem, not the worker's end
            reply = (ident, False, f"{type(error).__name__}: {error}")
        replies.write(frame(reply))
        replies.flush()


def main() -> None:
    # Planning is background work: under `softplc run --rt-priority` the worker would inherit
    # SCHED_FIFO and could starve the scan on a small machine.
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    # The answers get stdout to themselves: anything else printed goes to stderr.
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    serve(sys.stdin.buffer, replies)


if __name__ == "__main__":
    main()
