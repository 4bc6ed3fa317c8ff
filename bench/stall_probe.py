"""An independent witness of machine stalls: a separate process that wakes every 1 ms.

    .venv/bin/python bench/stall_probe.py SECONDS     # prints JSON on stdout when done

It does nothing but sleep and note how late each wake-up is, so when it is late by many
milliseconds the whole machine (a virtual machine's host, the kernel) stalled — not softplc.
The benchmarks run it beside softplc and report the stalls both saw at the same moment.
Prints {"max_ms": ..., "stalls": [[monotonic_time, late_ms], ...]} with every wake-up more
than 5 ms late.
"""

from __future__ import annotations

import json
import sys
import time

PERIOD = 0.001
STALL = 0.005


def probe(seconds: float) -> dict[str, object]:
    end = time.monotonic() + seconds
    stalls: list[list[float]] = []
    worst = 0.0
    due = time.monotonic()
    while True:
        due += PERIOD
        now = time.monotonic()
        if now >= end:
            break
        if due > now:
            time.sleep(due - now)
        woke = time.monotonic()
        late = woke - due
        worst = max(worst, late)
        if late > STALL:
            stalls.append([round(woke, 4), round(late * 1e3, 2)])
            due = woke  # one stall is one entry, not one per missed period
    return {"max_ms": round(worst * 1e3, 3), "stalls": stalls}


if __name__ == "__main__":
    print(json.dumps(probe(float(sys.argv[1]))))
