"""A real coordinator for the redundancy tests: Debian's etcd-server (3.4) on free loopback ports.

scripts/install-test-tools.sh installs it. One node is enough for tests (a plant runs three,
docs/redundancy.md). Tuned for a short lease, as docs/redundancy.md says: heartbeat 50 ms and
election timeout 500 ms, so etcd takes a 1 s lease as it is (it raises any TTL below 1.5 ×
the election timeout). `stop()` kills it (its data stays), `start()` brings it back on the same
ports with the same data: the leases it held survive a restart.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

HEARTBEAT_MS = 50
ELECTION_TIMEOUT_MS = 500


class EtcdUnavailable(RuntimeError):
    """No etcd on this machine."""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class EtcdServer:
    """One etcd process; `endpoint` is what a `redundancy.coordinator.endpoints` entry names."""

    def __init__(self) -> None:
        binary = shutil.which("etcd") or ("/usr/bin/etcd" if Path("/usr/bin/etcd").is_file() else None)
        if binary is None:
            raise EtcdUnavailable("etcd not found (apt-get install etcd-server, or scripts/install-test-tools.sh)")
        self.binary = binary
        self.port = free_port()
        self.peer_port = free_port()
        self.directory = Path(tempfile.mkdtemp(prefix="softplc-etcd-"))
        self.log = self.directory / "etcd.log"
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def endpoint(self) -> str:
        return f"127.0.0.1:{self.port}"

    def command(self) -> list[str]:
        client, peer = f"http://127.0.0.1:{self.port}", f"http://127.0.0.1:{self.peer_port}"
        return [self.binary, "--name", "test", "--data-dir", str(self.directory / "data"),
                "--listen-client-urls", client, "--advertise-client-urls", client,
                "--listen-peer-urls", peer, "--initial-advertise-peer-urls", peer, "--initial-cluster", f"test={peer}",
                "--heartbeat-interval", str(HEARTBEAT_MS), "--election-timeout", str(ELECTION_TIMEOUT_MS),
                "--log-level", "warn"]

    def start(self, timeout: float = 15.0) -> None:
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(self.command(), stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"etcd exited with {self.process.returncode}: {self.log.read_text()[-2000:]}")
            if self._healthy():
                return
            time.sleep(0.05)
        raise RuntimeError(f"etcd did not answer on {self.port} within {timeout} s")

    def _healthy(self) -> bool:
        import urllib.request

        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/health", timeout=0.5) as reply:
                return b'"true"' in reply.read()
        except OSError:
            return False

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)
        self.process = None

    def remove(self) -> None:
        self.stop()
        shutil.rmtree(self.directory, ignore_errors=True)
