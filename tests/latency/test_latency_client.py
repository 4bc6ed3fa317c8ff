"""The handshake client's report of one answer: which Ready it answered, and when that was set."""

from __future__ import annotations

from typing import Any

from softplc.latency.client import HandshakeClient
from softplc.latency.driver import Snapshot


def _report(ready: Snapshot, after: Snapshot) -> dict[str, Any]:
    events: list[dict[str, Any]] = []
    client = HandshakeClient(None, events.append, samples=1, duration=None, timeout=1.0)  # type: ignore[arg-type]
    assert client._report(1, 2, ready, after, 4, ready.received + 0.0001, ready.received + 0.002, False) == "ok"
    (event,) = events
    return event


def test_the_stamp_read_after_the_answer_belongs_to_the_ready_answered():
    # A subscription pushes Ready alone; its stamp is read after the PLC took the answer.
    event = _report(Snapshot(ready=True, received=100.0), Snapshot(ready=False, task_id=2, handshakes=5, ready_stamp=99.9994, delay=1.0))
    assert event["ready_stamp"] == 99.9994 and not event.get("stamp_lost")


def test_a_stamp_of_the_plcs_next_ready_is_not_taken_for_the_answered_one():
    """A client held up longer than the next task (a busy machine) reads the stamp of the PLC's next
    Ready: set after the client saw the one it answered. Taken for it, the hi-res delay came out
    negative (seen: -129 ms); it is unknown instead, and counted."""
    event = _report(Snapshot(ready=True, received=100.0), Snapshot(ready=True, task_id=2, handshakes=5, ready_stamp=100.15, delay=1.0))
    assert event["ready_stamp"] is None and event["stamp_lost"] is True
    assert event["status"] == "ok" and event["plc_delay_ms"] == 1.0  # the PLC's own figures stand
