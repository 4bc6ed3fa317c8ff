"""The origin of a write or a command: the path it came by, the user, the peer address, the role."""

from __future__ import annotations

from dataclasses import dataclass

from softplc.core.roles import Role


@dataclass(frozen=True, slots=True)
class Origin:
    """Who asked for a write or a command: the path it came by, the user and the peer address, and the role.

    `role=None` is code inside the runtime (robot drivers, the runtime itself): no access rule
    applies and its writes are not reported to write listeners. A client always has a role.
    """

    source: str  # "opcua", "modbus", "hmi", "cli", "fleet:r01"...
    user: str = ""
    peer: str = ""
    role: Role | None = Role.OPERATOR

    @property
    def internal(self) -> bool:
        return self.role is None

    def __str__(self) -> str:
        who = self.user or ""
        if self.peer:
            who = f"{who}@{self.peer}" if who else self.peer
        return f"{self.source}:{who}" if who else self.source


def origin_of(origin: Origin | str) -> Origin:
    """An Origin; a plain string is shorthand for an operator client of that name (scripts, tests)."""
    return origin if isinstance(origin, Origin) else Origin(origin)
