"""A real MQTT broker for the tests: Debian's mosquitto on a free loopback port, with a config file of our own.

scripts/install-test-tools.sh installs it. `MosquittoServer(port)` can be stopped and started
again on the same port (a broker restart), `remove()` at the end deletes its folder; `extra` adds config lines (ACLs, a password file,
a message size limit).
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path


class MosquittoUnavailable(RuntimeError):
    """No mosquitto on this machine."""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class MosquittoServer:
    """One mosquitto process; `url` is what an `mqtt:` section names."""

    def __init__(self, port: int | None = None, extra: str = "") -> None:
        binary = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").is_file() else None)
        if binary is None:
            raise MosquittoUnavailable("mosquitto not found (apt-get install mosquitto, or scripts/install-test-tools.sh)")
        self.binary = binary
        self.port = port or free_port()
        self.directory = Path(tempfile.mkdtemp(prefix="softplc-mosquitto-"))
        self.config = self.directory / "mosquitto.conf"
        self.config.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n{extra}")
        self.log = self.directory / "mosquitto.log"
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self, timeout: float = 10.0) -> None:
        with self.log.open("ab") as log:
            self.process = subprocess.Popen([self.binary, "-c", str(self.config)], stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"mosquitto exited with {self.process.returncode}: {self.log.read_text()[-2000:]}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError(f"mosquitto did not listen on {self.port} within {timeout} s")

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)
        self.process = None

    def remove(self) -> None:
        """Stop the broker and delete its config and log: the end of its life."""
        self.stop()
        shutil.rmtree(self.directory, ignore_errors=True)
