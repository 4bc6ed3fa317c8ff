"""The runtime's side of `softplc robot-agent`: registrations answered, reports published, heartbeats.

A remote robot (`driver: remote`) has a `RemoteLink`: it accepts the agent's registration
(answering in `rNN_agent`, see softplc.robotics.protocol), publishes each report to the robot's
read-only tags and marks them BAD while the agent is silent. A robot the runtime drives itself
(`driver: sim`) has an `AgentRefusal`: an agent that registers for it is refused with the
reason, so a second copy of the robot never drives; the runtime logs that once a minute at most.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from softplc.core.tagdb import Origin, TagDatabase
from softplc.core.tags import Quality
from softplc.robotics.protocol import Answer, Registration, decode_report
from softplc.robotics.robots import RobotSpec

log = logging.getLogger(__name__)

PUBLISHED_TAGS = ("xpos", "ypos", "heading", "speed", "navstate", "navreason", "route")
LOG_EVERY = 60.0  # s between two log lines about refused agents of one robot


def _registration(robot_id: str, text: str) -> Registration | None:
    """The registration in `text`; None for an empty tag, our own answer, or garbage (logged)."""
    if not text or Answer.decode(text) is not None:
        return None
    try:
        return Registration.decode(text)
    except ValueError as error:
        log.warning("robot %s: ignoring a bad registration: %s", robot_id, error)
        return None


def _answer(db: TagDatabase, robot_id: str, source: Origin, registration: Registration, accepted: bool, reason: str = "") -> None:
    db.submit([(f"{robot_id}_agent", Answer(registration.session, accepted, reason).encode())], source)


class AgentRefusal:
    """Refuses every agent that registers for a robot this runtime drives itself."""

    def __init__(self, db: TagDatabase, spec: RobotSpec, robots_file: Path, now: Callable[[], float]) -> None:
        self.db = db
        self.id = spec.id
        self.reason = (f"the runtime drives robot {spec.id} itself (driver: sim in {robots_file}); "
                       f"declare it 'driver: remote' there to drive it with softplc robot-agent")
        self._now = now
        self.refused = 0
        self._logged_at: float | None = None
        self._unlogged = 0
        self.source = Origin(f"fleet:{spec.id}", role=None)

    def on_agent(self, text: str) -> None:
        registration = _registration(self.id, text)
        if registration is None:
            return
        self.refused += 1
        _answer(self.db, self.id, self.source, registration, False, self.reason)
        now = self._now()
        if self._logged_at is not None and now - self._logged_at < LOG_EVERY:
            self._unlogged += 1
            return
        more = f" ({self._unlogged} more since the last line)" if self._unlogged else ""
        log.error("robot %s: refused a robot agent from %s (pid %s): %s%s", self.id, registration.host or "?",
                  registration.pid, self.reason, more)
        self._logged_at, self._unlogged = now, 0


class RemoteLink:
    """The runtime's side of a remote robot: registration, reports in, heartbeat watch, quality BAD when away."""

    def __init__(self, db: TagDatabase, spec: RobotSpec, now: Any, timeout: float) -> None:
        self.db = db
        self.spec = spec
        self.id = spec.id
        self._now = now
        self.timeout = timeout
        self.online = False
        self.last_seen = -1.0
        self.registration: Registration | None = None
        self.reports = 0
        self.rejected = 0
        self._status_seq: int | None = None
        self._published = [f"{spec.id}_{name}" for name in PUBLISHED_TAGS]
        self.source = Origin(f"fleet:{spec.id}:remote", role=None)

    def go_offline(self, why: str) -> None:
        if self.online:
            log.warning("remote robot %s is away (%s): its tags are BAD until it reports again", self.id, why)
        self.online = False
        self.db.submit_quality(self._published, Quality.BAD, self.source)
        self.db.submit([(f"{self.id}_online", False)], self.source)

    def on_agent(self, text: str) -> None:
        registration = _registration(self.id, text)
        if registration is None:
            return
        if registration.id != self.id:
            log.warning("robot %s: an agent registered as %r in its tag; refused", self.id, registration.id)
            _answer(self.db, self.id, self.source, registration, False, f"this is robot {self.id}'s tag, not {registration.id}'s")
            return
        self.registration = registration
        self._status_seq = None  # a new agent session numbers its status events afresh
        expected = sorted(item.value for item in self.spec.hardware)
        if registration.hardware and sorted(registration.hardware) != expected:
            log.warning("robot %s registered with hardware %s, robots.yaml says %s", self.id, registration.hardware, expected)
        log.info("robot %s (%s) registered from %s (pid %s, %s)", self.id, registration.name, registration.host or "?", registration.pid, registration.software)
        _answer(self.db, self.id, self.source, registration, True)

    def on_report(self, text: str) -> None:
        if not text:
            return
        try:
            report = decode_report(text)
        except ValueError as error:
            self.rejected += 1
            log.warning("robot %s: ignoring a bad report: %s", self.id, error)
            return
        self.reports += 1
        self.last_seen = self._now()
        items: list[tuple[str, Any]] = [
            (f"{self.id}_xpos", report.x), (f"{self.id}_ypos", report.y), (f"{self.id}_heading", report.heading),
            (f"{self.id}_speed", report.speed), (f"{self.id}_navstate", report.navstate), (f"{self.id}_navreason", report.reason),
            (f"{self.id}_route", report.route),
        ]
        if not self.online:
            self.online = True
            items.append((f"{self.id}_online", True))
            log.info("remote robot %s is online", self.id)
        if report.status is not None and report.status_seq != self._status_seq:
            self._status_seq = report.status_seq
            items.append((f"{self.id}_status", report.status))
        for rejected in self.db.submit(items, self.source):
            if rejected is not None:
                log.warning("robot %s: %s", self.id, rejected)

    def check(self) -> None:
        if self.online and self._now() - self.last_seen > self.timeout:
            self.go_offline(f"no report for {self.timeout:g} s")
