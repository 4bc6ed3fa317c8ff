"""Password hashes: salted scrypt, with the cost parameters in the hash string.

A hash looks like `scrypt$17$8$1$<salt>$<hash>` (log2 N, r, p, base64 salt and digest), so the
default cost can rise without breaking old entries: each is checked with its own parameters.
The default is OWASP's minimum for scrypt (N=2^17, r=8, p=1: ~128 MB and ~0.4 s per check);
the server checks logins in a worker thread, one at a time, and remembers successes
(see logins.py), so a user pays it once per process.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os

SCRYPT_LOG2_N, SCRYPT_R, SCRYPT_P = 17, 8, 1
MIN_LOG2_N, MAX_LOG2_N = 10, 18
_MAX_MEMORY = 320 * 1024 * 1024  # N=2^18, r=8 needs 256 MB; a costlier hash string is refused


def hash_password(password: str, log2_n: int = SCRYPT_LOG2_N) -> str:
    """A salted scrypt hash string for `password`; `log2_n` below the default is for tests and embedded use."""
    if not MIN_LOG2_N <= log2_n <= MAX_LOG2_N:
        raise ValueError(f"scrypt cost log2(N) must be between {MIN_LOG2_N} and {MAX_LOG2_N}")
    salt = os.urandom(16)
    digest = _scrypt(password, salt, log2_n, SCRYPT_R, SCRYPT_P)
    return f"scrypt${log2_n}${SCRYPT_R}${SCRYPT_P}${_b64(salt)}${_b64(digest)}"


def verify_password(password: str, stored: str) -> bool:
    """Whether `password` matches a hash string made by `hash_password` (slow: call it off the loop)."""
    try:
        scheme, log2_n, r, p, salt, digest = stored.split("$")
        if scheme != "scrypt" or not MIN_LOG2_N <= int(log2_n) <= MAX_LOG2_N:
            return False
        expected = base64.b64decode(digest)
        actual = _scrypt(password, base64.b64decode(salt), int(log2_n), int(r), int(p))
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(actual, expected)


def dummy_hash() -> str:
    """A hash of the default cost that no password matches: checked for unknown user names."""
    return f"scrypt${SCRYPT_LOG2_N}${SCRYPT_R}${SCRYPT_P}${_b64(os.urandom(16))}${_b64(os.urandom(32))}"


def _scrypt(password: str, salt: bytes, log2_n: int, r: int, p: int) -> bytes:
    return hashlib.scrypt(password.encode("utf-8"), salt=salt, n=2**log2_n, r=r, p=p, maxmem=_MAX_MEMORY, dklen=32)


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")
