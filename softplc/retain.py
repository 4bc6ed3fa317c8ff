"""Retained tags: values kept across restarts in a SQLite file (one transaction per flush)."""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)


class RetainStore:
    """`name → (type, value)` rows in `retain.sqlite`; writes are atomic transactions.

    The runtime saves from an executor thread (a commit waits for the disk), so the connection
    may be used from any thread, one at a time.
    """

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._lock = threading.Lock()
        self._db = sqlite3.connect(path, check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        self._db.execute("CREATE TABLE IF NOT EXISTS retain (name TEXT PRIMARY KEY, type TEXT NOT NULL, value TEXT NOT NULL)")
        self._db.commit()

    def load(self) -> dict[str, tuple[str, Any]]:
        with self._lock:
            rows = self._db.execute("SELECT name, type, value FROM retain").fetchall()
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
