"""asyncua's user manager over the users file (`softplc.security.users`): password, certificate, anonymous."""

from __future__ import annotations

import logging
from typing import Any

from asyncua.crypto.permission_rules import UserRole
from asyncua.server.user_managers import UserManager

from softplc.adapters.opcua.roles import SessionUser
from softplc.core.roles import Role
from softplc.security.logins import PasswordLogins
from softplc.security.users import UserStore

log = logging.getLogger(__name__)


class SoftplcUserManager(UserManager):
    """asyncua user manager: users file logins, certificate logins, optional anonymous viewer.

    Never grants asyncua's Admin role, so AccessLevel and node management rules always apply.
    A password login must have been decided by `check_password` (awaited by the transport
    before asyncua activates the session); `get_user` never hashes on the event loop.
    """

    def __init__(self, store: UserStore, anonymous: Role | None) -> None:
        self.store = store
        self.anonymous = anonymous
        self.logins = PasswordLogins(store)

    async def check_password(self, peer: str, username: str, password: str) -> bool:
        """Decide a password login from address `peer` off the event loop (throttled)."""
        return await self.logins.check(peer, username, password)

    def get_user(
        self, iserver: Any, username: str | None = None, password: str | None = None, certificate: Any = None
    ) -> SessionUser | None:
        self.store.refresh()
        if username:
            entry = self.logins.decided(username, password or "")
            if entry is None:
                log.warning("OPC UA: login of %r refused: its password was not checked ahead", username)
                return None
            return SessionUser(role=UserRole.User, name=entry.name, access=entry.role)
        if certificate:
            # A certificate here was proven: either an X509 identity token's signature was
            # checked, or it is the certificate of the secured channel the session runs on.
            entry = self.store.by_certificate(bytes(certificate))
            if entry is not None:
                return SessionUser(role=UserRole.User, name=entry.name, access=entry.role)
        if self.anonymous is not None:
            return SessionUser(role=UserRole.User, name="anonymous", access=self.anonymous)
        return None

    def close(self) -> None:
        self.logins.close()
