"""What one latency measurement produced: the answered handshakes (`Sample`) and everything counted."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from softplc.latency.target import Target

Progress = Callable[["Measurement"], None]


@dataclass
class Sample:
    """One answered handshake with its client timestamps (monotonic s) and the PLC's figures."""

    index: int
    task_id: int
    status: str  # ok | missed | start (the warm-up answer that started the sequence)
    ready_stamp: float | None
    t_seen: float
    t_sent: float
    t_done: float
    plc_delay_ms: float | None
    plc_delay_scans: int | None
    plc_handshakes: int | None

    @classmethod
    def from_event(cls, event: dict[str, Any]) -> Sample:
        return cls(**{name: event.get(name) for name in cls.__dataclass_fields__})  # type: ignore[arg-type]

    def hires_ms(self, same_clock: bool) -> float | None:
        """Ready set in the PLC → TaskID write acknowledged by it: the protocol's share of the delay."""
        if not same_clock or self.ready_stamp is None:
            return None
        return (self.t_done - self.ready_stamp) * 1000.0

    def notify_ms(self, same_clock: bool) -> float | None:
        """Ready set in the PLC → the client saw it (push or poll)."""
        if not same_clock or self.ready_stamp is None:
            return None
        return (self.t_seen - self.ready_stamp) * 1000.0

    def respond_ms(self) -> float:
        """The client saw Ready → its write was acknowledged."""
        return (self.t_done - self.t_seen) * 1000.0


@dataclass
class Measurement:
    """Everything one run produced, counted."""

    target: Target
    label: str = ""  # shown instead of the protocol in reports (e.g. a baseline's name)
    endpoint: str = ""
    same_clock: bool = False
    driver: str = ""
    samples: list[Sample] = field(default_factory=list)
    warmup: list[Sample] = field(default_factory=list)
    timeouts: int = 0
    missed: int = 0  # a Ready never answered, or an answer the PLC did not take
    unreported: int = 0  # answered, but the client died before reporting it
    foreign: int = 0  # switches the PLC counted that another client made
    stamps_lost: int = 0  # samples without a hi-res delay: their ReadyStamp was overwritten before it was read
    errors: list[str] = field(default_factory=list)
    client_pid: int | None = None
    client_exit: int | None = None
    client_stderr: list[str] = field(default_factory=list)
    started: float = field(default_factory=time.time)
    wall_seconds: float = 0.0
    plc_task: dict[str, Any] = field(default_factory=dict)  # scan statistics of our runtime
    conditions: dict[str, Any] = field(default_factory=dict)

    connected: bool = False  # the client connected and said hello
    ended: str = ""  # why the run ended: complete, interrupted by the user, client died (…), …
    activity: str = ""  # what the run is waiting for now, when that is not the client's next report
    missed_notes: list[str] = field(default_factory=list)  # context of missed handshakes found after the client
    client_gone_at: float | None = None  # monotonic time the client's output ended

    @property
    def ok_samples(self) -> list[Sample]:
        return [sample for sample in self.samples if sample.status == "ok"]

    @property
    def complete(self) -> bool:
        return self.client_exit == 0 and not self.errors

    @property
    def not_attempted(self) -> int | None:
        """Requested samples never attempted (the run ended first); None for a --duration run."""
        if self.target.samples is None or self.target.duration is not None:
            return None
        attempted = len(self.samples) + len(self.missed_notes) + self.unreported
        return max(0, self.target.samples - attempted)


def interrupted(result: Measurement, stop: asyncio.Event, when: str = "") -> bool:
    """True (and recorded) when the user has asked to stop."""
    if not stop.is_set():
        return False
    if not result.ended:
        result.ended = "interrupted by the user"
        result.errors.append("interrupted by the user" + when)
    return True
