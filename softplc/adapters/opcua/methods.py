"""The Call service with the statuses of OPC UA Part 4 (5.11.2) for calls that cannot be made.

asyncua 2.1.0 (pinned) answers a Call whose object or method does not exist with BadNodeIdInvalid
(the NodeId is well-formed; it names nothing) and a method without an implementation with
BadNothingToDo. Here, per CallMethodRequest:

    BadNodeIdUnknown     the ObjectId names no node
    BadMethodInvalid     the MethodId names no node, or a node that is not a Method
    BadNotImplemented    a Method of the standard address space that this server does not implement

Anything else is asyncua's (softplc itself defines no methods).
"""

from __future__ import annotations

from asyncua import ua
from asyncua.server.address_space import MethodService


class CheckedMethodService(MethodService):
    """asyncua's method service with Part 4 statuses for unknown objects and methods."""

    async def _call(self, method: ua.CallMethodRequest) -> ua.CallMethodResult:
        if method.ObjectId not in self._aspace:
            return _refused(ua.StatusCodes.BadNodeIdUnknown)
        node = self._aspace.get(method.MethodId)
        if node is None or _node_class(node) != ua.NodeClass.Method:
            return _refused(ua.StatusCodes.BadMethodInvalid)
        if node.call is None:
            return _refused(ua.StatusCodes.BadNotImplemented)
        return await super()._call(method)


def _refused(code: int) -> ua.CallMethodResult:
    return ua.CallMethodResult(StatusCode=ua.StatusCode(code))


def _node_class(node: object) -> object:
    attribute = node.attributes.get(ua.AttributeIds.NodeClass)  # type: ignore[attr-defined]
    value = attribute.value if attribute is not None else None
    return value.Value.Value if value is not None and value.Value is not None else None
