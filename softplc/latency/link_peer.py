"""`softplc latency --client link`: the handshake answered by a second softplc runtime joined by a link (PLC to PLC).

Our runtime serves the handshake plant as for any client (measurement.py). The answering side is
`softplc run` of programs/handshake_answer.yaml in its own process, its `links:` section pointed
at our server (OPC UA by subscription with an operator login, or Modbus by polling every
`--poll-interval`), its task at the same `--scan`. Nothing of it reports to us: the samples are
taken in our runtime, where the answer lands —

- `t_done`: our server took the answer (the TaskID write, reported by the tag database's write listener);
- `t_seen` (= `t_sent`): the answering program saw Ready (its `SeenStamp`, written to our `AnswerSeen`
  in the same answer; system-wide monotonic time);
- the PLC's `Delay`, `DelayScans` and `Handshakes`, when `Handshakes` counts the switch.

The first answer (TaskID 0 → 1) starts the sequence: a warm-up, not counted. A run ends after
the samples or the duration asked for, at Ctrl-C, after three handshake timeouts in a row, or
when the answering runtime dies (its last lines are reported).
"""

from __future__ import annotations

import asyncio
import collections
import os
import sys
import time
from pathlib import Path
from typing import Any

import yaml

from softplc.latency.results import Measurement, Progress, Sample, interrupted
from softplc.latency.target import Target
from softplc.util.realtime import format_cpus

ANSWER_YAML = Path(__file__).resolve().parents[2] / "programs" / "handshake_answer.yaml"
OPCUA_SOURCES = {"Ready": "ns={ns};s=Ready", "TaskID": "ns={ns};s=TaskID", "SeenStamp": "ns={ns};s=AnswerSeen"}
MAX_TIMEOUTS = 3
START_ALLOWANCE = 60.0  # s for the answering runtime to start and answer the first Ready


def answer_config(target: Target, endpoint: str, directory: Path, source: Path = ANSWER_YAML) -> Path:
    """The answering plant for this run: its link pointed at `endpoint`, its task at the run's scan."""
    data = yaml.safe_load(source.read_text())
    scan = f"{target.scan * 1000:g}ms"
    data["tasks"]["answer"]["interval"] = scan
    data["tasks"]["answer"]["watchdog"] = f"{max(target.scan * 1000, 5):g}ms"
    data["tasks"]["answer"]["programs"][0]["program"] = f"{source.parent / 'handshake_answer.py'}:HandshakeAnswer"
    if target.protocol == "opcua":
        (directory / "answer.password").write_text((target.password or "") + "\n")
        (directory / "answer.password").chmod(0o600)
        data["links"] = {"plc": {
            "protocol": "opcua", "endpoint": endpoint, "user": target.user, "password_file": "answer.password",
            "namespace": target.namespace or "urn:softplc:tags", "publishing_interval": f"{target.publishing_interval_ms:g}ms",
            "period": "100ms", "timeout": "2s",
        }}
        for tag, node in OPCUA_SOURCES.items():
            data["tags"][tag]["link"]["source"] = node
    else:
        host, _, port = endpoint.rpartition(":")
        data["links"]["plc"].update({"host": host, "port": int(port), "unit": target.unit_id,
                                     "period": f"{target.poll_interval_ms:g}ms"})
    path = directory / "handshake_answer.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


async def run_link_peer(target: Target, result: Measurement, progress: Progress, stop: asyncio.Event, plant: Any, state: Path) -> None:
    """Start the answering runtime, take the samples in `plant` (our runtime), stop it; fill `result`."""
    observer = Observer(plant, result)
    config = answer_config(target, result.endpoint, state)
    env = {**os.environ, "PYTHONPATH": str(ANSWER_YAML.parents[1]) + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH") else "")}
    placement = ["--cpus", format_cpus(target.client_cpus)] if target.client_cpus is not None else []
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "softplc", "run", str(config), "--state-dir", str(state / "answer-state"), "--no-status", *placement,
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE, env=env,
    )
    result.client_pid = process.pid
    result.driver = f"softplc {config.name} (pid {process.pid}), a {target.protocol} link"
    result.label = f"{'OPC UA' if target.protocol == 'opcua' else 'Modbus'} PLC-PLC {target.scan * 1000:g}ms"
    tail: collections.deque[str] = collections.deque(maxlen=40)
    reading = asyncio.ensure_future(_drain(process.stderr, tail))
    started = time.monotonic()
    try:
        await observer.follow(target, progress, stop, process)
    finally:
        result.client_gone_at = time.monotonic()
        observer.close()
        exited = process.returncode
        if exited is None:
            process.terminate()
            try:
                await asyncio.wait_for(process.wait(), 10)
            except TimeoutError:
                process.kill()
                await process.wait()
        await asyncio.gather(reading, return_exceptions=True)
        result.client_stderr = list(tail)
        result.wall_seconds = time.monotonic() - started
        # We stopped it: that is its normal end. Ending by itself is not.
        result.client_exit = 0 if exited is None else exited
        if exited is not None:
            result.ended = "client died"
            last = next((line for line in reversed(tail) if line.strip()), "")
            result.errors.append(f"the answering runtime exited with code {exited}" + (f": {last}" if last else ""))


class Observer:
    """Turns what the answering runtime does to our plant into samples (see the module docstring)."""

    def __init__(self, plant: Any, result: Measurement) -> None:
        self.db = plant.db
        self.result = result
        self.seen: float | None = None  # the AnswerSeen of the answer being taken
        self.done: tuple[float, int] | None = None  # (t_done, TaskID) of the last answer our server took
        self.new_sample = asyncio.Event()
        self._undo = [self.db.on_write(self._written), self.db.on_change(self._changed)]
        self.last_handshakes = self.db.value("Handshakes")
        self.started = False
        self.waiting: tuple[dict[str, Any], float] | None = None  # a switch waiting for its AnswerSeen

    def close(self) -> None:
        for undo in self._undo:
            undo()
        self._undo = []

    def _written(self, events: Any) -> None:
        now = time.monotonic()
        for event in events:
            if not event.accepted:
                continue
            if event.tag == "AnswerSeen":
                self.seen = float(event.new)
                if self.waiting is not None:  # a switch already counted, whose AnswerSeen came in a later request (Modbus)
                    self._record(*self.waiting)
            elif event.tag == "TaskID" and event.new in (1, 2, 3):
                self.done = (now, int(event.new))

    def _changed(self, tags: Any) -> None:
        names = {tag.name for tag in tags}
        if not self.started and "RunningTask" in names and self.db.value("RunningTask") != 0 and self.done is not None:
            self.started = True
            self.result.connected = True
            self._take("start")
        if "Handshakes" in names and self.db.value("Handshakes") != self.last_handshakes:
            self.last_handshakes = self.db.value("Handshakes")
            self._take("ok")

    def _take(self, status: str) -> None:
        """The PLC's figures of the answer just taken; recorded once its AnswerSeen is in too."""
        if self.waiting is not None:
            self._record(*self.waiting)  # its AnswerSeen never came: t_seen falls back to t_done
        db = self.db
        t_done, task = self.done if self.done is not None else (time.monotonic(), 0)
        figures = {"task_id": task, "status": status, "ready_stamp": db.value("ReadyStamp"), "t_done": t_done,
                   "plc_delay_ms": db.value("Delay"), "plc_delay_scans": db.value("DelayScans"), "plc_handshakes": db.value("Handshakes")}
        self.waiting = (figures, time.monotonic())
        if self.seen is not None and self.seen >= figures["ready_stamp"]:
            self._record(*self.waiting)

    def _record(self, figures: dict[str, Any], taken: float) -> None:
        self.waiting = None
        seen = self.seen if self.seen is not None and self.seen >= figures["ready_stamp"] else figures["t_done"]
        self.seen = None
        result = self.result
        kind = result.warmup if figures["status"] == "start" else result.samples
        kind.append(Sample(index=0 if kind is result.warmup else len(result.samples), t_seen=seen, t_sent=seen, **figures))
        self.new_sample.set()

    def flush(self, patience: float = 0.2) -> None:
        """A switch counted longer than `patience` ago whose AnswerSeen never came is recorded without it."""
        if self.waiting is not None and time.monotonic() - self.waiting[1] >= patience:
            self._record(*self.waiting)

    async def follow(self, target: Target, progress: Progress, stop: asyncio.Event, process: asyncio.subprocess.Process) -> None:
        """Until the run is complete, interrupted, timed out or the answering runtime dies."""
        result = self.result
        begun = time.monotonic()
        exited = asyncio.ensure_future(process.wait())
        stopping = asyncio.ensure_future(stop.wait())
        timeouts_in_row = 0
        try:
            while True:
                if target.samples is not None and target.duration is None and len(result.samples) >= target.samples:
                    result.ended = "complete"
                    return
                if target.duration is not None and result.connected and time.monotonic() - begun >= target.duration:
                    result.ended = "complete"
                    return
                wait = target.ready_timeout() if result.connected else START_ALLOWANCE
                self.new_sample.clear()
                sampled = asyncio.ensure_future(self.new_sample.wait())
                done, _ = await asyncio.wait({sampled, exited, stopping}, timeout=0.25 if self.waiting else wait,
                                             return_when=asyncio.FIRST_COMPLETED)
                sampled.cancel()
                if not done and self.waiting is not None:
                    self.flush()
                    continue
                if stopping in done:
                    interrupted(result, stop)
                    return
                if exited in done:
                    return  # run_link_peer reports the exit
                if sampled in done:
                    timeouts_in_row = 0
                    result.wall_seconds = time.monotonic() - begun
                    progress(result)
                    continue
                if not result.connected:
                    result.ended = "client never answered"
                    result.errors.append(f"the answering runtime did not answer the first Ready within {wait:g} s")
                    return
                result.timeouts += 1
                timeouts_in_row += 1
                if timeouts_in_row >= MAX_TIMEOUTS:
                    result.ended = "client stopped answering"
                    result.errors.append(f"no handshake within {wait:g} s, {MAX_TIMEOUTS} times in a row")
                    return
        finally:
            exited.cancel()
            stopping.cancel()


async def _drain(stream: asyncio.StreamReader | None, tail: collections.deque[str]) -> None:
    if stream is None:
        return
    async for line in stream:
        tail.append(line.decode(errors="replace").rstrip())
