"""The OPC UA session user that carries a role (`softplc.core.roles`), and asyncua's service-level rules.

What each role may do is the core's (`softplc.core.roles`, enforced by `TagDatabase.validate`): the
same for OPC UA, Modbus, the HMI and the CLI. Nobody may add or delete nodes or references.
"""

from __future__ import annotations

from dataclasses import dataclass

from asyncua import ua
from asyncua.crypto.permission_rules import ADMIN_TYPES, USER_TYPES, PermissionRuleset, User, UserRole

from softplc.core.roles import ROLE_NAMES, Role

__all__ = ["ROLE_NAMES", "Role", "RolePermissions", "SessionUser", "role_of"]


@dataclass
class SessionUser(User):
    """An authenticated OPC UA session's user: asyncua's User plus our role."""

    access: Role = Role.VIEWER
    peer: str = ""  # the client's address, set when its session is activated


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
