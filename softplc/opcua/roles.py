"""Who may do what over OPC UA: the three roles and the session user that carries one.

- viewer: browse, read, subscribe. Every write → BadUserAccessDenied.
- operator: as viewer, plus write `rw` tags. Writing an `ro` tag → BadNotWritable.
- engineer: everything a client can do here: also writes `ro` tags (like forcing a value from a
  PLC programming tool; the program or driver that owns the tag overwrites it the next time it
  changes its output). Nobody may add or delete nodes or references.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from asyncua import ua
from asyncua.crypto.permission_rules import ADMIN_TYPES, USER_TYPES, PermissionRuleset, User, UserRole


class Role(enum.Enum):
    VIEWER = "viewer"
    OPERATOR = "operator"
    ENGINEER = "engineer"

    @property
    def may_write(self) -> bool:
        return self is not Role.VIEWER

    @property
    def may_write_read_only(self) -> bool:
        return self is Role.ENGINEER


ROLE_NAMES: tuple[str, ...] = tuple(role.value for role in Role)


@dataclass
class SessionUser(User):
    """An authenticated OPC UA session's user: asyncua's User plus our role."""

    access: Role = Role.VIEWER


def role_of(user: User | None) -> Role | None:
    """The role of a session's user; None for the server's own internal session."""
    if isinstance(user, SessionUser):
        return user.access
    if user is not None and user.role == UserRole.Admin:
        return None  # asyncua's internal session (code inside this process)
    return Role.VIEWER


class RolePermissions(PermissionRuleset):
    """Service-level rules: every role may use the ordinary services, nobody the node-management ones.

    Write is allowed at this level for every role so that each item gets its own status
    (BadUserAccessDenied for a viewer) instead of one ServiceFault for the whole request.
    """

    def __init__(self) -> None:
        # asyncua's list lacks BrowseNext, which transport.py serves (Browse continuation points).
        self._allowed = {ua.NodeId(type_id) for type_id in (*USER_TYPES, ua.ObjectIds.BrowseNextRequest_Encoding_DefaultBinary)}
        self._forbidden = {ua.NodeId(type_id) for type_id in ADMIN_TYPES}

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: object) -> bool:
        if action_type_id in self._forbidden:
            return False
        if not isinstance(user, SessionUser):
            return False  # only users our user manager created reach the network services
        return action_type_id in self._allowed
