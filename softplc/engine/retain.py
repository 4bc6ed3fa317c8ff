"""Retained tags: values kept across restarts in a SQLite file (one transaction per flush)."""

from __future__ import annotations

import json
import logging
import shutil
import sqlite3
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

class RetainError(Exception):
    """The retained values cannot be read; the file has not been changed. `corrupt`: its content is bad."""

    def __init__(self, path: Path, detail: str, *, corrupt: bool) -> None:
        super().__init__(f"{path}: {detail}")
        self.path = path
        self.detail = detail
        self.corrupt = corrupt


class RetainStore:
    """`name → (type, value)` rows in `retain.sqlite`; writes are atomic transactions.

    Opening checks the whole file (SQLite's quick_check reads every page: a few ms for the few
    hundred rows of a plant) on a copy, and raises RetainError rather than use a damaged file.
    The runtime saves from an executor thread (a commit waits for the disk), so the connection
    may be used from any thread, one at a time.
    """

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._lock = threading.Lock()
        if path.exists():
            _check_a_copy(path)
        try:
            self._db = sqlite3.connect(path, check_same_thread=False)
        except sqlite3.Error as error:
            raise _retain_error(path, error) from None
        try:
            _prepare(self._db, path)
        except (sqlite3.Error, RetainError) as error:
            self._db.close()
            if isinstance(error, RetainError):
                raise
            raise _retain_error(path, error) from None

    def load(self) -> dict[str, tuple[str, Any]]:
        try:
            with self._lock:
                rows = self._db.execute("SELECT name, type, value FROM retain").fetchall()
        except sqlite3.Error as error:
            raise _retain_error(self.path, error) from None
        result: dict[str, tuple[str, Any]] = {}
        for name, type_name, text in rows:
            try:
                result[name] = (type_name, json.loads(text))
            except json.JSONDecodeError:
                log.warning("retained value of %s in %s is unreadable; using its initial value", name, self.path)
        return result

    def save(self, values: dict[str, tuple[str, Any]]) -> None:
        if not values:
            return
        with self._lock, self._db:
            self._db.executemany(
                "INSERT INTO retain(name, type, value) VALUES (?, ?, ?) "
                "ON CONFLICT(name) DO UPDATE SET type = excluded.type, value = excluded.value",
                [(name, type_name, json.dumps(value)) for name, (type_name, value) in values.items()],
            )

    def close(self) -> None:
        with self._lock:
            self._db.close()


def open_retained(path: Path, corrupt: str, wall: float) -> tuple[RetainStore, dict[str, tuple[str, Any]]]:
    """The store at `path` and its values. A corrupt file raises RetainError (`corrupt="refuse"`)
    or is set aside, loudly, for a new empty store (`corrupt="initial"`; `wall`: epoch seconds now)."""
    try:
        store = RetainStore(path)
        try:
            return store, store.load()
        except RetainError:
            store.close()
            raise
    except RetainError as error:
        if not error.corrupt or corrupt == "refuse":
            raise
        try:
            kept = set_aside(path, time.strftime("%Y%m%dT%H%M%S", time.localtime(wall)))
        except OSError as rename_error:
            raise RetainError(path, f"{error.detail}, and cannot be set aside: {rename_error}", corrupt=False) from None
        log.error("RETAINED VALUES LOST: %s is %s. It is kept as %s for inspection; every retained tag "
                  "starts at its initial value", path, error.detail, kept)
        return RetainStore(path), {}


def set_aside(path: Path, suffix: str) -> Path:
    """Rename a bad retain file (and its WAL and shared-memory files) to `NAME.corrupt-SUFFIX`; return the new path."""
    target = path.with_name(f"{path.name}.corrupt-{suffix}")
    n = 1
    while target.exists():
        n += 1
        target = path.with_name(f"{path.name}.corrupt-{suffix}-{n}")
    # The WAL first: a new database at `path` must never replay the old file's journal.
    for extension in ("-wal", "-shm"):
        companion = path.with_name(path.name + extension)
        if companion.exists():
            companion.rename(target.with_name(target.name + extension))
    path.rename(target)
    return target


def _prepare(db: sqlite3.Connection, path: Path) -> None:
    """Set the connection up and check the whole file (of `path`); raise sqlite3.Error or RetainError."""
    db.execute("PRAGMA journal_mode=WAL")  # the first read of the file: "not a database" shows here
    db.execute("PRAGMA synchronous=FULL")
    # Every page: a damaged page a plain read does not touch (an index) would break the next save.
    problems = [row[0] for row in db.execute("PRAGMA quick_check").fetchall()]
    if problems != ["ok"]:
        first = " ".join(problems[0].replace("*** in database main ***", "").split())
        raise RetainError(path, f"damaged: SQLite's integrity check found: {first}", corrupt=True)
    db.execute("CREATE TABLE IF NOT EXISTS retain (name TEXT PRIMARY KEY, type TEXT NOT NULL, value TEXT NOT NULL)")
    db.commit()
    db.execute("SELECT name, type, value FROM retain LIMIT 0")


def _check_a_copy(path: Path) -> None:
    """Check a copy of the file (and its WAL) first: opening a bad file could write to it or beside it
    (a checkpoint, new -wal and -shm files), and it must stay exactly as it is."""
    with tempfile.TemporaryDirectory(prefix="softplc-retain-check-") as scratch:
        copy = Path(scratch) / path.name
        try:
            shutil.copyfile(path, copy)
            wal = path.with_name(path.name + "-wal")
            if wal.exists():
                shutil.copyfile(wal, copy.with_name(copy.name + "-wal"))
        except OSError as error:
            raise RetainError(path, f"cannot be read: {error}", corrupt=False) from None
        db = sqlite3.connect(copy)
        try:
            _prepare(db, path)
        except sqlite3.Error as error:
            raise _retain_error(path, error) from None
        finally:
            db.close()


def _retain_error(path: Path, error: sqlite3.Error) -> RetainError:
    code = getattr(error, "sqlite_errorname", "")
    if code == "SQLITE_NOTADB":
        return RetainError(path, f"not an SQLite database ({error})", corrupt=True)
    if code.startswith("SQLITE_CORRUPT"):
        return RetainError(path, f"damaged ({error})", corrupt=True)
    if isinstance(error, sqlite3.OperationalError) and "no such column" in str(error):
        return RetainError(path, f"not a softplc retain file: its table 'retain' has other columns ({error})", corrupt=True)
    return RetainError(path, f"cannot be read: {error}", corrupt=False)
