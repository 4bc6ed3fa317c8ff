"""How a remote robot agent and the runtime talk, through two string tags per robot.

- `rNN_agent`: written once per connection — who the agent is (JSON: id, name, hardware, host,
  pid, software, session). The fleet adapter logs it, checks it against robots.yaml and answers
  in the same tag (`Answer`: accepted, or refused with the reason — e.g. the runtime drives that
  robot itself, `driver: sim`); the agent drives only once accepted. The robot registers
  itself, nobody types its address.
- `rNN_report`: written every control cycle — the robot's pose and navigation state (JSON).
  The fleet adapter publishes it to the robot's read-only tags (`rNN_xpos`, ...), so clients
  cannot spoof a robot's position through those tags, and every report is a heartbeat.

Status changes travel as numbered events (`status_seq`): several reports may land between two
scan cycles, and a `status` cleared in one of them must not be lost.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

from softplc.robotics.driver import NavState, Report


@dataclass
class Registration:
    """What an agent says about itself when it connects."""

    id: str
    name: str = ""
    hardware: list[str] = field(default_factory=list)
    host: str = ""
    pid: int = 0
    software: str = ""
    session: str = ""  # changes on every (re)connection

    def encode(self) -> str:
        return json.dumps(asdict(self), separators=(",", ":"))

    @classmethod
    def decode(cls, text: str) -> Registration:
        data = _object(text)
        if "answer" in data:
            raise ValueError("this is the runtime's answer, not a registration")
        if not isinstance(data.get("id"), str):
            raise ValueError("registration has no robot id")
        known = {key: data[key] for key in cls.__dataclass_fields__ if key in data}
        return cls(**known)


@dataclass
class Answer:
    """The runtime's answer to a registration, written over it in `rNN_agent`."""

    session: str  # the registration's session
    accepted: bool
    reason: str = ""

    def encode(self) -> str:
        return json.dumps({"answer": "accepted" if self.accepted else "refused", "session": self.session, "reason": self.reason},
                          separators=(",", ":"))

    @classmethod
    def decode(cls, text: str) -> Answer | None:
        """The answer in `text`, or None when `text` is not an answer (e.g. a registration)."""
        try:
            data = _object(text)
        except ValueError:
            return None
        if data.get("answer") not in ("accepted", "refused"):
            return None
        return cls(str(data.get("session", "")), data["answer"] == "accepted", str(data.get("reason", "")))


def encode_report(seq: int, report: Report, status_seq: int, status: bool | None) -> str:
    """The JSON text of one report (`status` is the value of event `status_seq`)."""
    data: dict[str, Any] = {
        "seq": seq,
        "x": round(report.x, 5),
        "y": round(report.y, 5),
        "heading": round(report.heading, 5),
        "speed": round(report.speed, 5),
        "navstate": report.navstate.value,
        "reason": report.reason,
        "route": report.route,
        "status_seq": status_seq,
    }
    if status is not None:
        data["status"] = status
    return json.dumps(data, separators=(",", ":"))


@dataclass
class RemoteReport:
    """A decoded report."""

    seq: int
    x: float
    y: float
    heading: float
    speed: float
    navstate: str
    reason: str
    status_seq: int
    status: bool | None
    route: str = ""


def decode_report(text: str) -> RemoteReport:
    """Parse a report; raise ValueError with a clear reason if it is malformed."""
    data = _object(text)
    try:
        navstate = NavState(data["navstate"]).value
        return RemoteReport(
            seq=int(data["seq"]),
            x=float(data["x"]),
            y=float(data["y"]),
            heading=float(data["heading"]),
            speed=float(data["speed"]),
            navstate=navstate,
            reason=str(data.get("reason", "")),
            status_seq=int(data.get("status_seq", 0)),
            status=bool(data["status"]) if "status" in data else None,
            route=str(data.get("route", "")),
        )
    except KeyError as error:
        raise ValueError(f"report lacks {error}") from None
    except (TypeError, ValueError) as error:
        raise ValueError(f"bad report: {error}") from None


def _object(text: str) -> dict[str, Any]:
    try:
        data = json.loads(text)
    except (TypeError, json.JSONDecodeError) as error:
        raise ValueError(f"not JSON: {error}") from None
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    return data
