"""Who may do what: the three roles, the same on every path (OPC UA, Modbus, HMI, CLI).

- viewer: browse, read, subscribe, look at history and alarms. Every write is refused.
- operator: as viewer, plus write `rw` tags, acknowledge, shelve and comment alarms.
- engineer: as operator, plus write `ro` tags (a commissioning override: the program or driver
  that owns the tag overwrites it the next time it changes its output), force tags, control
  programs (start, stop, restart, online change) and reset faults.

Nobody, whatever the role, writes a diagnostic `_sys.` tag: only the documented command tags
(`_sys.reset_stats`, `_sys.reset_faults`...) accept client writes. The tag database enforces
this (`TagDatabase.validate`), so every adapter gets the same answer for the same write.
"""

from __future__ import annotations

import enum


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

    @property
    def may_acknowledge(self) -> bool:
        """Acknowledge, shelve and comment alarms."""
        return self is not Role.VIEWER

    @property
    def may_engineer(self) -> bool:
        """Force tags, control and change programs, reset faults."""
        return self is Role.ENGINEER


ROLE_NAMES: tuple[str, ...] = tuple(role.value for role in Role)
