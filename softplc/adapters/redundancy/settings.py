"""The `redundancy:` section: the pair's two members, the coordinator (etcd) and this runtime's name in it.

    redundancy:
      preferred: a                       # the member that becomes active when both start at once
      members:                           # exactly two; the same file on both machines
        a: {sync: "10.0.0.1:7101", certificate: pair/a.crt, key: pair/a.key,
            opcua: "opc.tcp://10.0.0.1:4840/softplc/", hmi: "http://10.0.0.1:8080/"}
        b: {sync: "10.0.0.2:7101", certificate: pair/b.crt, key: pair/b.key, ...}
      coordinator: {endpoints: ["10.0.0.5:2379", "10.0.0.6:2379", "10.0.0.7:2379"], lease: 1s}

Which member this runtime is comes from `softplc run --redundancy-member NAME`, else
`$SOFTPLC_REDUNDANCY_MEMBER`, else `member:` in the section. Paths are relative to the file.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.config.schema import DURATION
from softplc.util.durations import check_duration, parse_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

MEMBER_ENV = "SOFTPLC_REDUNDANCY_MEMBER"
ADDRESS = {"type": "string", "pattern": r"^[^\s:]+:[0-9]{1,5}$", "description": "HOST:PORT"}

MEMBER_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "sync": {**ADDRESS, "description": "where the peer reaches this member's sync link (HOST:PORT)"},
        "listen": {**ADDRESS, "description": "where this member listens for it, when not at `sync` (behind a NAT or a proxy)"},
        "certificate": {"type": "string", "description": "this member's sync-link certificate (PEM): pinned by the peer"},
        "key": {"type": "string", "description": "this member's private key (PEM); only needed on its own machine"},
        "opcua": {"type": "string", "description": "its OPC UA endpoint, as clients reach it"},
        "hmi": {"type": "string", "description": "its HMI's address, as browsers reach it"},
    },
    "required": ["sync", "certificate"],
    "additionalProperties": False,
}

SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "member": {"type": "string", "description": "this runtime's name (else --redundancy-member or $SOFTPLC_REDUNDANCY_MEMBER)"},
        "preferred": {"type": "string", "description": "the member that becomes active when both start at once"},
        "members": {"type": "object", "additionalProperties": MEMBER_SCHEMA, "minProperties": 2, "maxProperties": 2},
        "coordinator": {
            "type": "object",
            "properties": {
                "endpoints": {"type": "array", "items": ADDRESS, "minItems": 1},
                "lease": DURATION,
                "key": {"type": "string", "pattern": "^/"},
            },
            "required": ["endpoints"],
            "additionalProperties": False,
        },
        "sync_lag_alarm": DURATION,
    },
    "required": ["members", "coordinator"],
    "additionalProperties": False,
}


@dataclass(frozen=True)
class Member:
    """One runtime of the pair, as the file declares it."""

    name: str
    sync: str
    certificate: Path
    key: Path | None = None
    listen: str = ""
    opcua: str = ""
    hmi: str = ""

    @property
    def listen_address(self) -> tuple[str, int]:
        host, _, port = (self.listen or self.sync).rpartition(":")
        return host, int(port)

    @property
    def sync_address(self) -> tuple[str, int]:
        host, _, port = self.sync.rpartition(":")
        return host, int(port)


@dataclass(frozen=True)
class RedundancySettings:
    """The pair, the coordinator, and who this runtime is."""

    plant: str
    me: Member
    peer: Member
    preferred: str
    endpoints: tuple[tuple[str, int], ...]
    lease: float = 1.0
    key: str = ""
    sync_lag_alarm: float = 1.0
    members: tuple[Member, ...] = field(default=())

    @property
    def lease_seconds(self) -> int:
        """The lease's TTL as etcd takes it: whole seconds, at least 1."""
        return max(1, math.ceil(self.lease - 1e-9))

    @property
    def election_key(self) -> str:
        return self.key or f"/softplc/{self.plant}/active"


class SettingsError(ValueError):
    """The section cannot make a pair here (who this runtime is, a missing file); the message says what to do."""


def member_name(section: dict[str, Any], wanted: str | None) -> str:
    """This runtime's name: --redundancy-member, else $SOFTPLC_REDUNDANCY_MEMBER, else `member:`."""
    name = wanted or os.environ.get(MEMBER_ENV) or section.get("member")
    members = sorted(section.get("members") or {})
    if not name:
        raise SettingsError(f"which member of the redundant pair is this runtime? give --redundancy-member {'|'.join(members)} "
                            f"(or ${MEMBER_ENV})")
    if name not in members:
        raise SettingsError(f"--redundancy-member {name}: the pair's members are {', '.join(members)}")
    return str(name)


def _endpoint(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return host, int(port)


def from_config(config: PlantConfig, wanted: str | None) -> RedundancySettings:
    """The settings of a checked configuration's section; raises SettingsError."""
    section = config.section("redundancy") or {}
    me = member_name(section, wanted)
    base = config.path.parent
    members = []
    for name, entry in sorted(section["members"].items()):
        members.append(Member(
            name=name, sync=entry["sync"], certificate=(base / entry["certificate"]).resolve(),
            key=(base / entry["key"]).resolve() if entry.get("key") else None, listen=entry.get("listen", ""),
            opcua=entry.get("opcua", ""), hmi=entry.get("hmi", ""),
        ))
    mine = next(member for member in members if member.name == me)
    peer = next(member for member in members if member.name != me)
    if mine.key is None:
        raise SettingsError(f"redundancy.members.{me}.key: this member's private key is not given (softplc redundancy keys makes a pair)")
    for path, what in ((mine.certificate, "certificate"), (mine.key, "key"), (peer.certificate, "peer's certificate")):
        if not path.is_file():
            raise SettingsError(f"the redundant pair's {what} {path} does not exist (softplc redundancy keys DIR makes them)")
    coordinator = section["coordinator"]
    return RedundancySettings(
        plant=config.name, me=mine, peer=peer, preferred=str(section.get("preferred") or members[0].name),
        endpoints=tuple(_endpoint(text) for text in coordinator["endpoints"]),
        lease=parse_duration(coordinator.get("lease", "1s")), key=str(coordinator.get("key", "")),
        sync_lag_alarm=parse_duration(section.get("sync_lag_alarm", "1s")), members=tuple(members),
    )


def problems(config: PlantConfig) -> list[Problem]:
    """What the schema cannot say: the preferred member, durations, ports."""
    section = config.section("redundancy")
    if section is None:
        return []
    found = []
    members = section.get("members") or {}
    preferred = section.get("preferred")
    if preferred is not None and preferred not in members:
        found.append(config.problem(("redundancy", "preferred"), f"preferred member {preferred!r} is not one of {', '.join(sorted(members))}"))
    member = section.get("member")
    if member is not None and member not in members:
        found.append(config.problem(("redundancy", "member"), f"member {member!r} is not one of {', '.join(sorted(members))}"))
    for key, where in (("lease", ("redundancy", "coordinator", "lease")), ("sync_lag_alarm", ("redundancy", "sync_lag_alarm"))):
        value = (section.get("coordinator") or {}).get("lease") if key == "lease" else section.get(key)
        if value is not None:
            _, message = check_duration(value, key)
            if message:
                found.append(config.problem(where, message))
    addresses = [(name, field_name, entry.get(field_name)) for name, entry in members.items() if isinstance(entry, dict)
                 for field_name in ("sync", "listen") if entry.get(field_name)]
    for name, field_name, text in addresses:
        port = int(str(text).rpartition(":")[2] or 0)
        if not 0 < port < 65536:
            found.append(config.problem(("redundancy", "members", name, field_name), f"port {port} is out of range 1-65535"))
    return found
