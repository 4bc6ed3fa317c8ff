"""`softplc write TAG=VALUE...`: values typed as text, parsed by each tag's type, written in one request.

The server is the judge: each item's OPC UA status is turned back into the runtime's rule
(`softplc.core.tagdb.Rule`) and the message the runtime gives for it — the same text as every other
client sees (`t01_iFr: out of range: 700.0 is above the maximum 600`). The detail is made by the
runtime's own validation (`TagDatabase.validate`) applied to what the server tells of the tag
(type, EURange, whether this session may write it), so it is word for word the runtime's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from asyncua import ua

from softplc.clients.session import LiveSession, TagInfo
from softplc.clients.tags.table import format_value
from softplc.core.datatypes import TypeMismatch
from softplc.core.roles import Role
from softplc.core.tagdb import Rule, TagDatabase, WriteRejected
from softplc.protocols.opcua_variants import variant_for

_CODE_RULES = {
    ua.StatusCodes.BadNodeIdUnknown: Rule.UNKNOWN_TAG,
    ua.StatusCodes.BadNotWritable: Rule.READ_ONLY,
    ua.StatusCodes.BadTypeMismatch: Rule.TYPE_MISMATCH,
    ua.StatusCodes.BadOutOfRange: Rule.OUT_OF_RANGE,
    ua.StatusCodes.BadUserAccessDenied: Rule.ACCESS_DENIED,
    ua.StatusCodes.BadLocked: Rule.FORCED,
    ua.StatusCodes.BadInvalidState: Rule.NOT_ACTIVE,
}
# Which role makes the runtime's validation give the rule's message (the rule itself is the server's).
_ROLE_FOR_RULE = {Rule.READ_ONLY: Role.OPERATOR, Rule.ACCESS_DENIED: Role.VIEWER, Rule.FORCED: Role.ENGINEER}


@dataclass(frozen=True)
class Assignment:
    """One TAG=VALUE of the command line."""

    tag: str
    text: str


def parse_assignments(items: list[str]) -> list[Assignment]:
    """TAG=VALUE items (the value may contain '='); raises ValueError for one without a tag and '='."""
    assignments = []
    for item in items:
        tag, equals, text = item.partition("=")
        if not equals or not tag.strip():
            raise ValueError(f"{item!r} is not TAG=VALUE (e.g. t01_iFr=45 or r01_status=true)")
        assignments.append(Assignment(tag.strip(), text))
    return assignments


@dataclass(frozen=True)
class WriteOutcome:
    """What became of one item: accepted (rule None) or refused by a rule, with the runtime's message."""

    tag: str
    value: Any
    old: Any = None
    rule: Rule | None = None
    detail: str = ""
    status: str = "Good"

    @property
    def accepted(self) -> bool:
        return self.rule is None

    def message(self) -> str:
        if self.rule is None:
            return f"{self.tag}: {format_value(self.old)} → {format_value(self.value)} (accepted: applied at the next scan cycle)"
        return f"{self.tag}: {self.rule.value}: {self.detail}"


async def write_tags(session: LiveSession, assignments: list[Assignment]) -> tuple[list[WriteOutcome], bool]:
    """Parse every value by its tag's type, then write all of them in one request; returns the outcomes and whether it was sent.

    If a value does not parse, nothing is sent (the outcomes say why). Raises UnknownTags.
    """
    tags = list(dict.fromkeys(a.tag for a in assignments))
    infos = await session.describe(tags)
    before = {reading.tag: reading for reading in await session.read(tags)}
    parsed: list[tuple[Assignment, Any]] = []
    refused: list[WriteOutcome] = []
    for assignment in assignments:
        definition = infos[assignment.tag].definition
        try:
            parsed.append((assignment, definition.type.parse(assignment.text)))
        except TypeMismatch as error:
            refused.append(WriteOutcome(assignment.tag, assignment.text, rule=Rule.TYPE_MISMATCH, detail=str(error)))
    if refused:
        return refused, False
    items = [(a.tag, variant_for(infos[a.tag].definition, value)) for a, value in parsed]
    try:
        statuses = await session.write(items)
    except ua.UaStatusCodeError as error:  # the whole request refused: every item shares its status
        statuses = [ua.StatusCode(error.code)] * len(items)
    outcomes = []
    for (assignment, value), status in zip(parsed, statuses):
        old = before[assignment.tag]
        if status.is_good():
            outcomes.append(WriteOutcome(assignment.tag, value, old.value))
            continue
        # A forced tag refuses client writes; the server shows the force as GoodLocalOverride.
        rule = Rule.FORCED if old.forced else _CODE_RULES.get(status.value, Rule.INVALID_REQUEST)
        if rule is Rule.NOT_ACTIVE:
            detail = await standby_detail(session)
        else:
            detail = runtime_detail(infos[assignment.tag], value, rule) or _status_text(status)
        outcomes.append(WriteOutcome(assignment.tag, value, old.value, rule, detail, status.name))
    return outcomes, True


async def standby_detail(session: LiveSession) -> str:
    """Why a redundant pair's member refused a write, naming the active (from its `_sys.redundancy.` tags)."""
    try:
        member, active, endpoint = (reading.value for reading in await session.read(
            ["_sys.redundancy.member", "_sys.redundancy.active", "_sys.redundancy.active_opcua"]))
    except Exception:  # not a member of a pair, or it went away
        return "this runtime is not the active one of its redundant pair: write to the active"
    if not active:
        return f"this runtime ({member}) is not active and no active is known now: try again shortly"
    return f"this runtime ({member}) is the standby of its redundant pair: write to the active, {active}" + (f" ({endpoint})" if endpoint else "")


def runtime_detail(info: TagInfo, value: Any, rule: Rule) -> str | None:
    """The runtime's own message for `rule` on this tag and value, or None if its validation finds another rule."""
    definition = info.definition
    db = TagDatabase([definition], now=lambda: 0.0)
    if rule is Rule.FORCED:
        db.force(definition.name, definition.type.default, "cli")
        db.apply_journal()
    try:
        db.validate(definition.name, value, role=_ROLE_FOR_RULE.get(rule))
    except WriteRejected as rejected:
        return rejected.detail if rejected.rule is rule else None
    return None


def _status_text(status: ua.StatusCode) -> str:
    return f"refused by the server: {status.name} ({status.doc})" if status.doc else f"refused by the server: {status.name}"

