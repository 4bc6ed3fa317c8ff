"""The Sparkplug B tests' independent host (tests/sparkplug/host.py, pysparkplug in its own venv) and a plant to publish.

    host = await SparkplugHost.start(broker.port, "plant1", host_id="scada")     # connected
    birth = await host.wait(lambda e: e["type"] == "NBIRTH")    # the runtime runs on the same loop meanwhile
    await host.send({"op": "rebirth", "node": "line1"})
    host.close()
"""

from __future__ import annotations

import asyncio
import json
import queue
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tools_support import missing

REPO = Path(__file__).resolve().parent.parent
HOST_SCRIPT = REPO / "tests" / "sparkplug" / "host.py"
HOST_PYTHON = REPO / "tests" / "sparkplug" / ".venv" / "bin" / "python"

Event = dict[str, Any]


def host_python() -> Path:
    """The host's interpreter; skips (fails under CI) when scripts/install-test-tools.sh has not made its venv."""
    if HOST_PYTHON.is_file():
        return HOST_PYTHON
    message = f"{HOST_PYTHON} is missing: scripts/install-test-tools.sh makes it (pysparkplug 0.6.1, paho-mqtt < 2)"
    missing(message)


class SparkplugHost:
    """A pysparkplug host as a subprocess: what it decodes arrives as events (dicts), commands go to its stdin."""

    def __init__(self, port: int, group: str, host_id: str = "") -> None:
        command = [str(host_python()), str(HOST_SCRIPT), "--port", str(port), "--group", group]
        if host_id:
            command += ["--host-id", host_id]
        self.process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        self.events: list[Event] = []
        self._queue: queue.Queue[Event] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    @classmethod
    async def start(cls, port: int, group: str, host_id: str = "") -> SparkplugHost:
        host = cls(port, group, host_id)
        await host.wait(lambda event: event["type"] == "ready", what="the host connected")
        return host

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._queue.put(json.loads(line))

    def _drain(self) -> None:
        while True:
            try:
                event = self._queue.get_nowait()
            except queue.Empty:
                return
            if event["type"] == "error":
                raise AssertionError(f"pysparkplug could not read a message: {event}")
            self.events.append(event)

    async def wait(self, condition: Callable[[Event], bool], timeout: float = 10.0, what: str = "an event", since: int = 0) -> Event:
        """The first event from index `since` on that meets `condition`, waiting up to `timeout` s (the loop runs meanwhile)."""
        deadline = time.monotonic() + timeout
        while True:
            self._drain()
            for event in self.events[since:]:
                if condition(event):
                    return event
            if time.monotonic() > deadline:
                seen = [f"{e['type']}/{e.get('device')}" for e in self.events[-20:]]
                raise AssertionError(f"{what}: not within {timeout} s; the host saw {seen}")
            if self.process.poll() is not None:
                raise AssertionError(f"the host exited: {self.process.stderr.read() if self.process.stderr else ''}")
            await asyncio.sleep(0.02)

    async def send(self, command: dict[str, Any], timeout: float = 10.0) -> None:
        """Send a command and wait until the host has published it."""
        assert self.process.stdin is not None
        marker = self.mark()
        self.process.stdin.write(json.dumps(command) + "\n")
        self.process.stdin.flush()
        await self.wait(lambda event: event["type"] == "done", timeout, f"the host to carry out {command['op']}", since=marker)

    def mark(self) -> int:
        """The index of the next event (to wait for what comes after now)."""
        self._drain()
        return len(self.events)

    def of(self, kind: str, device: str | None = None, since: int = 0) -> list[Event]:
        self._drain()
        return [e for e in self.events[since:] if e["type"] == kind and (device is None or e.get("device") == device)]

    def close(self) -> None:
        if self.process.poll() is None:
            try:
                assert self.process.stdin is not None
                self.process.stdin.write(json.dumps({"op": "quit"}) + "\n")
                self.process.stdin.flush()
                self.process.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self.process.kill()
                self.process.wait(timeout=5)


def metric(event: Event, name: str) -> dict[str, Any]:
    """The metric `name` of an event (pysparkplug resolved aliases to names)."""
    return next(m for m in event["metrics"] if m["name"] == name)


def check_seq(events: list[Event], node: str) -> None:
    """Within each session (from an NBIRTH to the next), the node's messages are numbered 0, 1, 2... mod 256."""
    expected = None
    for event in events:
        if event.get("node") != node or event["type"] in ("NDEATH",):
            continue
        if event["type"] == "NBIRTH":
            assert event["seq"] == 0, f"an NBIRTH with seq {event['seq']}"
            expected = 1
            continue
        if expected is None:
            continue  # before the first birth the host saw
        assert event["seq"] == expected, f"seq {event['seq']} where {expected} was due: {event['type']}/{event.get('device')}"
        expected = (expected + 1) % 256
