"""Users: a YAML file of names, roles and salted password hashes (or certificate fingerprints).

One users file serves every path that logs in: OPC UA sessions and the HMI.

File format (written by `softplc users add/remove`; default `<state_dir>/users.yaml`):

    users:
      alice:  {role: operator, password: "scrypt$17$8$1$<salt>$<hash>"}
      robot7: {role: operator, certificate: "<SHA-256 fingerprint of its client certificate>"}

Passwords are stored as scrypt hashes (passwords.py); they are checked off the event loop,
throttled and remembered by logins.py (`PasswordLogins`), whichever server asks.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from softplc.config.yamlsource import ConfigError, load_yaml
from softplc.core.roles import ROLE_NAMES, Role
from softplc.security.passwords import SCRYPT_LOG2_N, hash_password, verify_password

log = logging.getLogger(__name__)

__all__ = ["UserEntry", "UserStore", "fingerprint", "hash_password", "normalise_fingerprint", "verify_password"]

USER_NAME_PATTERN = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")
MIN_PASSWORD_LENGTH = 8
HEADER = "# softplc users (OPC UA and HMI). Manage with: softplc users add NAME --role ROLE | softplc users list | softplc users remove NAME\n"


def fingerprint(der: bytes) -> str:
    """SHA-256 fingerprint of a DER certificate as lowercase hex (64 characters)."""
    return hashlib.sha256(der).hexdigest()


def normalise_fingerprint(text: str) -> str:
    """Accept 'AB:CD:…', 'sha256:abcd…' or a hex prefix; return lowercase hex without separators."""
    text = text.strip().lower()
    if text.startswith("sha256:"):
        text = text[len("sha256:"):]
    return re.sub(r"[^0-9a-f]", "", text)


@dataclass(frozen=True)
class UserEntry:
    """One user of the file."""

    name: str
    role: Role
    password_hash: str | None = None
    certificate: str | None = None  # SHA-256 fingerprint, lowercase hex


class UserStore:
    """The users file: read (re-read when it changes), edited by the CLI, asked at login."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._users: dict[str, UserEntry] = {}
        self._stamp: tuple[int, int] | None = None
        self.reload()

    # -- reading ----------------------------------------------------------------------

    def reload(self) -> None:
        """(Re)read the file if it changed; a missing file means no users. Raises ConfigError."""
        try:
            stat = self.path.stat()
        except FileNotFoundError:
            self._users, self._stamp = {}, None
            return
        stamp = (stat.st_mtime_ns, stat.st_size)
        if stamp == self._stamp:
            return
        self._users = _parse(self.path)
        self._stamp = stamp

    def refresh(self) -> None:
        """Reload if changed; keep the old users (and log) if the new file is broken."""
        try:
            self.reload()
        except ConfigError as error:
            log.error("users file %s is invalid, keeping the previous users: %s", self.path, error)

    def __contains__(self, name: object) -> bool:
        return name in self._users

    def get(self, name: str) -> UserEntry | None:
        return self._users.get(name)

    def entries(self) -> list[UserEntry]:
        return list(self._users.values())

    def by_certificate(self, der: bytes) -> UserEntry | None:
        wanted = fingerprint(der)
        for entry in self._users.values():
            if entry.certificate == wanted:
                return entry
        return None

    @property
    def has_certificate_users(self) -> bool:
        return any(entry.certificate for entry in self._users.values())

    # -- editing (CLI) ------------------------------------------------------------------

    def add(self, name: str, role: Role, password: str | None = None, certificate: str | None = None,
            *, log2_n: int = SCRYPT_LOG2_N) -> UserEntry:
        """Add or replace a user; needs a password or a certificate fingerprint.

        `log2_n` is the password hash's cost (scrypt N = 2**log2_n); lower it only for tests and
        embedded use, where logging in must be fast and the users file is not exposed.
        """
        if not USER_NAME_PATTERN.match(name):
            raise ValueError(f"invalid user name '{name}': use 1-64 letters, digits and _ . @ -")
        if password is None and certificate is None:
            raise ValueError("a user needs a password or a certificate")
        if password is not None and len(password) < MIN_PASSWORD_LENGTH:
            raise ValueError(f"the password must have at least {MIN_PASSWORD_LENGTH} characters")
        print_ = normalise_fingerprint(certificate) if certificate else None
        if print_ is not None and len(print_) != 64:
            raise ValueError("the certificate fingerprint must be the full SHA-256 (64 hex digits)")
        entry = UserEntry(name, role, hash_password(password, log2_n) if password is not None else None, print_)
        self._users[name] = entry
        self.save()
        return entry

    def remove(self, name: str) -> None:
        if name not in self._users:
            raise KeyError(name)
        del self._users[name]
        self.save()

    def save(self) -> None:
        """Write the file atomically, readable by its owner only."""
        data: dict[str, Any] = {"users": {}}
        for entry in self._users.values():
            item: dict[str, str] = {"role": entry.role.value}
            if entry.password_hash:
                item["password"] = entry.password_hash
            if entry.certificate:
                item["certificate"] = entry.certificate
            data["users"][entry.name] = item
        self.path.parent.mkdir(parents=True, exist_ok=True)
        temporary = self.path.with_name(self.path.name + ".tmp")
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as handle:
            handle.write(HEADER)
            yaml.safe_dump(data, handle, sort_keys=False, default_flow_style=False)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, self.path)
        stat = self.path.stat()
        self._stamp = (stat.st_mtime_ns, stat.st_size)


def _parse(path: Path) -> dict[str, UserEntry]:
    data, source = load_yaml(path)
    problems = []
    users: dict[str, UserEntry] = {}
    table = data.get("users") if isinstance(data, dict) else None
    if data is not None and not isinstance(table, (dict, type(None))):
        raise ConfigError([source.problem(("users",), "'users' must be a mapping of user name → {role, password}")])
    for name, spec in (table or {}).items():
        where = ("users", name)
        if not isinstance(spec, dict):
            problems.append(source.problem(where, f"user '{name}' must be a mapping with role and password"))
            continue
        role_name = spec.get("role")
        if role_name not in ROLE_NAMES:
            at = (*where, "role") if "role" in spec else where
            problems.append(source.problem(at, f"user '{name}': role must be one of {', '.join(ROLE_NAMES)}"))
            continue
        password, certificate = spec.get("password"), spec.get("certificate")
        texts = all(isinstance(item, (str, type(None))) for item in (password, certificate))
        if not texts or (password is None and certificate is None):
            problems.append(source.problem(where, f"user '{name}' needs a password hash (softplc users add) or a certificate fingerprint"))
            continue
        users[str(name)] = UserEntry(str(name), Role(role_name), password, normalise_fingerprint(certificate) if certificate else None)
    if problems:
        raise ConfigError(problems)
    return users
