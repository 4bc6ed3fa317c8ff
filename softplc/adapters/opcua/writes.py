"""Client writes, validated per item like a PLC, and journaled into the tag database.

asyncua's own Write path checks only AccessLevel and exact Variant types, lets Admin bypass
both, and writes straight into the address space. A PreWrite callback cannot veto an item.
So the server's attribute service is replaced (`iserver.attribute_service`, the object every
session's Write goes through) by `TagAttributeService`, which answers each item of a Write:

    Good                      valid: journaled, applied at the next scan-cycle boundary
    BadNodeIdUnknown          no such node
    BadNotWritable            a folder, a property, an attribute other than Value, an `ro`
                              tag written by an operator, or a diagnostic `_sys.` tag
    BadUserAccessDenied       the session's role may not write (viewer, anonymous)
    BadTypeMismatch           wrong type (see `variants.value_from_variant` for the lossless
                              conversions accepted)
    BadOutOfRange             outside the tag's min/max, or outside its type's range
    BadLocked                 the tag is forced (softplc/core/forcing.py): unforce it first
    BadWriteNotSupported      a StatusCode other than Good (clients cannot set quality)
    BadIndexRangeInvalid      an IndexRange (tags are scalars)

The access rules are the tag database's (`TagDatabase.validate`, `softplc.core.roles`), the same for
every protocol; each item of a Write is submitted with the session's `Origin` (user, the
client's address, role), so the database reports it, accepted or refused, to its write
listeners (the audit trail).

UserAccessLevel, as read by a client session, tells what *its* role may do (a PostRead hook,
`TagAttributeService.user_access_level`): CurrentRead|CurrentWrite (3) on the tags the role may
write — `rw` tags for an operator, every tag but the diagnostic `_sys.` ones for an engineer — and
CurrentRead (1) elsewhere (every tag for a viewer or an anonymous session; folders, properties
and asyncua's nodes for all).

Nothing of an invalid item is applied; valid items of the same Write are journaled together,
so a scan sees all of them or none. The address space is never written here: it follows the
tag database (see `publisher.py`), so a read right after a Write returns the old value until
the next cycle boundary (at most one task interval), exactly as a PLC answers.

Same tag written by a client and a program in one cycle: the journal is applied at the start
of the cycle, so the program sees the client's value in its input image; if the program then
writes a different value, the program's value wins (it decided knowing the client's value).
A program that does not assign the output leaves the client's value in place.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from asyncua import ua
from asyncua.common.callback import CallbackService, ServerItemCallback
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.server.address_space import AddressSpace, AttributeService

from softplc.adapters.opcua.roles import role_of
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, TagDatabase, WriteRejected
from softplc.protocols.opcua_variants import WriteStatus, value_from_variant

log = logging.getLogger(__name__)

# Requests bigger than this are refused whole (BadTooManyOperations), so one client cannot
# hold the event loop (and the scan) for long with a single huge Read or Write.
MAX_NODES_PER_READ = 20_000
MAX_NODES_PER_WRITE = 5_000
_YIELD_EVERY = 500
_CURRENT_WRITE = ua.AccessLevel.CurrentWrite.mask

_RULE_CODES = {
    Rule.UNKNOWN_TAG: ua.StatusCodes.BadNodeIdUnknown,
    Rule.READ_ONLY: ua.StatusCodes.BadNotWritable,
    Rule.TYPE_MISMATCH: ua.StatusCodes.BadTypeMismatch,
    Rule.OUT_OF_RANGE: ua.StatusCodes.BadOutOfRange,
    Rule.ACCESS_DENIED: ua.StatusCodes.BadUserAccessDenied,
    Rule.FORCED: ua.StatusCodes.BadLocked,  # "locked by a different application": an engineer's force
    Rule.INVALID_REQUEST: ua.StatusCodes.BadInvalidArgument,  # e.g. an item of an all-or-nothing batch
    # The standby of a redundant pair; ServerRedundancy (ServiceLevel, ServerUriArray) and
    # _sys.redundancy.active tell the client where the active is (docs/redundancy.md).
    Rule.NOT_ACTIVE: ua.StatusCodes.BadInvalidState,
}
_CODE_RULES = {
    ua.StatusCodes.BadTypeMismatch: Rule.TYPE_MISMATCH,
    ua.StatusCodes.BadOutOfRange: Rule.OUT_OF_RANGE,
    ua.StatusCodes.BadNodeIdUnknown: Rule.UNKNOWN_TAG,
}


class TagAttributeService(AttributeService):
    """asyncua's attribute service with our Write: per-item validation into the write journal."""

    def __init__(self, aspace: AddressSpace, db: TagDatabase, namespace_index: int) -> None:
        super().__init__(aspace)
        self.db = db
        self.ns = namespace_index
        self.accepted = 0
        self.rejected = 0

    def read(self, params: ua.ReadParameters) -> list[ua.DataValue]:
        if len(params.NodesToRead) > MAX_NODES_PER_READ:
            raise ServiceError(ua.StatusCodes.BadTooManyOperations)
        return super().read(params)

    def user_access_level(self, event: ServerItemCallback, _: CallbackService) -> None:
        """PostRead hook: replace each UserAccessLevel read by what the session's role may do."""
        role = role_of(event.user)
        if role is None:
            return  # the server's own code: the stored value
        results: list[ua.DataValue] = event.response_params
        for index, item in enumerate(event.request_params.NodesToRead):
            if item.AttributeId != ua.AttributeIds.UserAccessLevel:
                continue
            stored = results[index].Value
            if stored is None or not isinstance(stored.Value, int):
                continue  # no such node or attribute: keep the error status
            node_id = item.NodeId
            writable = node_id.NamespaceIndex == self.ns and isinstance(node_id.Identifier, str) and self.db.writable(node_id.Identifier, role)
            results[index] = _access_level(stored.Value | _CURRENT_WRITE if writable else stored.Value & ~_CURRENT_WRITE)

    async def write(self, params: ua.WriteParameters, user: User = User(role=UserRole.Admin)) -> list[ua.StatusCode]:
        items = params.NodesToWrite
        if len(items) > MAX_NODES_PER_WRITE:
            raise ServiceError(ua.StatusCodes.BadTooManyOperations)
        role = role_of(user)
        origin = Origin("opcua", getattr(user, "name", None) or ("internal" if role is None else "anonymous"),
                        peer=getattr(user, "peer", ""), role=role)
        results: list[ua.StatusCode | None] = [None] * len(items)
        batch: list[tuple[str, Any]] = []
        batch_indexes: list[int] = []
        foreign: list[int] = []
        for index, item in enumerate(items):
            if index and index % _YIELD_EVERY == 0:
                await asyncio.sleep(0)  # a long request must not hold the scan
            if item.NodeId.NamespaceIndex != self.ns or not isinstance(item.NodeId.Identifier, str):
                if role is None:
                    foreign.append(index)  # the server's own code writing a standard node
                else:
                    results[index] = self._not_ours(item.NodeId)
                continue
            try:
                name, value = self._check(item, role)
            except WriteStatus as refused:
                results[index] = ua.StatusCode(refused.code)
                rule = _CODE_RULES.get(refused.code, Rule.INVALID_REQUEST)
                self._refused(origin, item, rule, refused.detail)
                continue
            except WriteRejected as rejected:
                results[index] = ua.StatusCode(_RULE_CODES[rejected.rule])
                self._refused(origin, item, rejected.rule, rejected.detail)
                continue
            batch.append((name, value))
            batch_indexes.append(index)
        # Valid items of one request enter the journal together: one cycle applies all of them.
        if batch:
            for index, rejected in zip(batch_indexes, self.db.submit(batch, origin)):
                if rejected is None:
                    results[index] = ua.StatusCode()
                else:
                    results[index] = ua.StatusCode(_RULE_CODES[rejected.rule])
                    log.info("%s: write %s refused: %s", origin, rejected.tag, rejected.detail)
        for index in foreign:
            single = ua.WriteParameters(NodesToWrite=[items[index]])
            results[index] = (await super().write(single, user))[0]
        accepted = sum(1 for status in results if status is not None and status.is_good())
        self.accepted += accepted
        self.rejected += len(items) - accepted
        return [status if status is not None else ua.StatusCode(ua.StatusCodes.BadInternalError) for status in results]

    def _refused(self, origin: Origin, item: ua.WriteValue, rule: Rule, detail: str) -> None:
        """Report an item refused here to the write listeners, and log it."""
        name = printable(item.NodeId.Identifier)
        self.db.refused(origin, name, printable(_variant_value(item)), rule, detail)
        log.info("%s: write %s refused: %s", origin, name, detail)

    def _not_ours(self, node_id: ua.NodeId) -> ua.StatusCode:
        if node_id in self._aspace:
            return ua.StatusCode(ua.StatusCodes.BadNotWritable)
        return ua.StatusCode(ua.StatusCodes.BadNodeIdUnknown)

    def _check(self, item: ua.WriteValue, role: Role | None) -> tuple[str, Any]:
        """(tag name, value) of an item the database should judge, else raise WriteStatus or WriteRejected.

        What the protocol alone decides (node, attribute, index range, quality, Variant type)
        is checked here; access is checked first, so a viewer hears BadUserAccessDenied whatever
        it sent. The value's range and the tag's type rules are the database's, in `submit`.
        """
        name = item.NodeId.Identifier
        tag = self.db.get(name)
        if tag is None:
            if item.NodeId in self._aspace:
                raise WriteStatus(ua.StatusCodes.BadNotWritable, "not a tag (folder or property)")
            raise WriteStatus(ua.StatusCodes.BadNodeIdUnknown, "no such tag")
        if item.AttributeId != ua.AttributeIds.Value:
            raise WriteStatus(ua.StatusCodes.BadNotWritable, f"attribute {item.AttributeId} is not writable")
        if item.IndexRange:
            raise WriteStatus(ua.StatusCodes.BadIndexRangeInvalid, "tags are scalars; no IndexRange")
        if role is not None:
            self.db.check_access(name, role)
        data = item.Value
        if data.StatusCode is not None and not data.StatusCode.is_good():
            raise WriteStatus(ua.StatusCodes.BadWriteNotSupported, "clients cannot write a tag's quality")
        return name, value_from_variant(tag.definition, data.Value)


def printable(value: Any) -> Any:
    """`value` with the undecodable bytes of a client's string shown as \\xNN (others unchanged).

    asyncua decodes every String with surrogateescape: invalid UTF-8 from a client arrives as
    lone surrogates, which a log file or an audit trail could not encode.
    """
    if isinstance(value, str):
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            return value.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    return value


def _variant_value(item: ua.WriteValue) -> Any:
    """What a refused item asked for, for the write listeners (None if it carried no value)."""
    variant = item.Value.Value if item.Value is not None else None
    return variant.Value if variant is not None else None


_ACCESS_LEVELS: dict[int, ua.DataValue] = {}


def _access_level(level: int) -> ua.DataValue:
    """A shared DataValue for a UserAccessLevel (never mutated)."""
    value = _ACCESS_LEVELS.get(level)
    if value is None:
        value = _ACCESS_LEVELS[level] = ua.DataValue(ua.Variant(level, ua.VariantType.Byte))
    return value
