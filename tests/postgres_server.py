"""A real PostgreSQL server for the tests: initdb + pg_ctl in a temp dir on a free loopback port.

Debian's `postgresql` package puts the server binaries in /usr/lib/postgresql/VERSION/bin
(scripts/install-test-tools.sh installs it). As root the server runs as the `postgres` user,
who must own its directory. One server per test session; each test gets its own schema.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path


class PostgresUnavailable(RuntimeError):
    """No PostgreSQL server binaries on this machine."""


def server_binaries() -> Path:
    """The directory holding initdb and pg_ctl (newest version first)."""
    override = os.environ.get("SOFTPLC_PG_BIN")
    candidates = [Path(override)] if override else sorted(Path("/usr/lib/postgresql").glob("*/bin"), key=_version, reverse=True)
    for directory in candidates:
        if (directory / "initdb").is_file() and (directory / "pg_ctl").is_file():
            return directory
    found = shutil.which("initdb")
    if found:
        return Path(found).parent
    raise PostgresUnavailable("PostgreSQL server binaries not found (apt-get install postgresql, or scripts/install-test-tools.sh)")


def _version(path: Path) -> float:
    try:
        return float(path.parent.name)
    except ValueError:
        return 0.0


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class PostgresServer:
    """A throw-away PostgreSQL cluster; `dsn` connects as the superuser `postgres` without a password."""

    def __init__(self) -> None:
        self.bin = server_binaries()
        self.directory = Path(tempfile.mkdtemp(prefix="softplc-pg-"))
        self.data = self.directory / "data"
        self.port = 0
        self._as_postgres = os.geteuid() == 0  # the server refuses to run as root

    def _run(self, *command: str) -> subprocess.CompletedProcess[str]:
        prefix = ["runuser", "-u", "postgres", "--"] if self._as_postgres else []
        return subprocess.run([*prefix, *command], capture_output=True, text=True, timeout=120, check=False)

    def start(self) -> None:
        if self._as_postgres:
            shutil.chown(self.directory, "postgres", "postgres")
        result = self._run(str(self.bin / "initdb"), "-D", str(self.data), "-A", "trust", "-U", "postgres", "--no-sync", "-E", "UTF8")
        if result.returncode != 0:
            raise RuntimeError(f"initdb failed: {result.stderr.strip() or result.stdout.strip()}")
        for _ in range(5):  # another process may take the free port before the server does
            self.port = _free_port()
            result = self._pg_ctl_start()
            if result.returncode == 0:
                return
        raise RuntimeError(f"pg_ctl start failed: {result.stderr.strip()} {self._log_tail()}")

    def _pg_ctl_start(self) -> subprocess.CompletedProcess[str]:
        options = f"-p {self.port} -k {self.directory} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=200"
        return self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-o", options, "-l", str(self.directory / "log"), "-w", "start")

    def _log_tail(self) -> str:
        return (self.directory / "log").read_text(errors="replace")[-2000:] if (self.directory / "log").exists() else ""

    def shut_down(self) -> None:
        """Stop the server as an administrator would (clients' connections are terminated); the data stays."""
        result = self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-m", "fast", "-w", "stop")
        if result.returncode != 0:
            raise RuntimeError(f"pg_ctl stop failed: {result.stderr.strip()}")

    def start_again(self) -> None:
        """Start a server stopped by `shut_down` on the same port."""
        result = self._pg_ctl_start()
        if result.returncode != 0:
            raise RuntimeError(f"pg_ctl start failed: {result.stderr.strip()} {self._log_tail()}")

    @property
    def dsn(self) -> str:
        return f"host=127.0.0.1 port={self.port} user=postgres dbname=postgres"

    def stop(self) -> None:
        if self.port:
            self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-m", "immediate", "-w", "stop")
        shutil.rmtree(self.directory, ignore_errors=True)

    def new_schema(self, name: str) -> str:
        """Create schema `name` and return a DSN whose tables live in it."""
        import psycopg

        with psycopg.connect(self.dsn, autocommit=True) as connection:
            connection.execute(f'DROP SCHEMA IF EXISTS "{name}" CASCADE')
            connection.execute(f'CREATE SCHEMA "{name}"')
        return f"{self.dsn} options='-c search_path={name}'"
