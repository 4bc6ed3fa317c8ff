"""The flood limit itself (softplc/util/log_limit.py), on a clock the test turns: kinds, the per-logger cap, summaries."""

from __future__ import annotations

import logging

from softplc.util.log_limit import FloodFilter


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def record(message: str, *args: object, logger: str = "softplc.adapters.opcua.writes", level: int = logging.INFO) -> logging.LogRecord:
    return logging.LogRecord(logger, level, __file__, 1, message, args, None)


def test_a_kind_is_limited_per_interval_and_summarised_when_it_closes() -> None:
    clock, summaries = Clock(), []
    flood = FloodFilter(summaries.append, burst=5, interval=10.0, now=clock)
    passed = [flood.filter(record("%s: write %s refused: %s", "opcua:anonymous", f"x{n}", "no")) for n in range(40)]
    assert passed == [True] * 5 + [False] * 35
    assert flood.filter(record("another kind %s", 1))  # other kinds are not held back
    clock.now = 10.0
    assert flood.filter(record("%s: write %s refused: %s", "opcua:anonymous", "y", "no"))  # a new interval
    (summary,) = summaries
    assert summary.name == "softplc.adapters.opcua.writes" and summary.levelno == logging.INFO
    assert summary.getMessage() == ("35 more lines like this left out in the last 10 s (at most 5 of a kind per 10 s): "
                                    "opcua:anonymous: write x5 refused: no")


def test_one_logger_is_capped_whatever_its_messages() -> None:
    """Messages made unique by what a client sent (an f-string) still count against their logger."""
    clock, summaries = Clock(), []
    flood = FloodFilter(summaries.append, burst=5, logger_burst=50, interval=10.0, now=clock)
    words = ["".join(chr(97 + (n // 26**i) % 26) for i in range(3)) for n in range(80)]
    passed = [flood.filter(record(f"unknown node {word}", logger="asyncua.server", level=logging.WARNING)) for word in words]
    assert passed.count(True) == 50 and passed[:50] == [True] * 50
    flood.close_windows(float("inf"))  # at exit
    (summary,) = summaries
    assert summary.levelno == logging.WARNING
    assert summary.getMessage().startswith("30 more lines of this logger left out in the last 10 s (at most 50 lines of one logger per 10 s)")


def test_preformatted_numbers_are_one_kind_and_debug_passes_when_unlimited() -> None:
    flood = FloodFilter(lambda r: None, burst=2, now=Clock())
    assert [flood.filter(record(f"frame {n} too long")) for n in range(4)] == [True, True, False, False]
    verbose = FloodFilter(lambda r: None, burst=2, unlimited_below=logging.INFO, now=Clock())
    assert all(verbose.filter(record("debug %d", n, level=logging.DEBUG)) for n in range(10))
