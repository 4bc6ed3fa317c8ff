"""`softplc watch` in a real pseudo-terminal: the table updates in place, shows F, ends on Ctrl-C and when the server goes away."""

from __future__ import annotations

import asyncio
import fcntl
import os
import pty
import re
import signal
import struct
import sys
import termios
import time
from pathlib import Path

from softplc.core.tagdb import Origin
from tests.clients.test_live_cli import force
from tests.conftest import REPO
from tests.opcua_support import running_plant

ROWS, COLUMNS = 30, 120


class Screen:
    """Just enough of a terminal to replay what `watch` writes: text, CR, LF, cursor up, erase to end of line."""

    def __init__(self) -> None:
        self.lines: list[str] = [""]
        self.row = self.column = 0

    def feed(self, text: str) -> None:
        for token in re.findall(r"\x1b\[\d*[A-Za-z]|\r|\n|[^\x1b\r\n]+", text):
            if token == "\r":
                self.column = 0
            elif token == "\n":
                self.row += 1
                if self.row == len(self.lines):
                    self.lines.append("")
            elif token.startswith("\x1b["):
                count = int(token[2:-1] or 1)
                if token.endswith("A"):
                    self.row = max(self.row - count, 0)
                elif token.endswith("K"):
                    self.lines[self.row] = self.lines[self.row][: self.column]
            else:
                line = self.lines[self.row].ljust(self.column)
                self.lines[self.row] = line[: self.column] + token + line[self.column + len(token):]
                self.column += len(token)

    def rows(self) -> dict[str, list[str]]:
        """The table's rows on screen, by tag (cells split on two or more spaces)."""
        found = {}
        for line in self.lines:
            cells = re.split(r"\s{2,}", line.strip())
            if len(cells) >= 3 and cells[2] in ("good", "uncertain", "bad"):
                found[cells[0]] = cells[1:]
        return found


class Terminal:
    """`softplc ARGS` as the foreground job of a new pseudo-terminal (so Ctrl-C reaches it through the tty)."""

    def __init__(self, *arguments: str, home: Path) -> None:
        env = dict(os.environ, PYTHONPATH=str(REPO), HOME=str(home), TERM="xterm")
        pid, fd = pty.fork()
        if pid == 0:  # the child: size the terminal, become softplc
            fcntl.ioctl(0, termios.TIOCSWINSZ, struct.pack("HHHH", ROWS, COLUMNS, 0, 0))
            os.execve(sys.executable, [sys.executable, "-m", "softplc.app.cli", *arguments], env)
        self.pid, self.fd = pid, fd
        self.output = ""
        self.screen = Screen()
        os.set_blocking(fd, False)

    def _read(self) -> None:
        while True:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                return
            except OSError:  # EIO: the child closed the terminal
                return
            if not chunk:
                return
            text = chunk.decode(errors="replace")
            self.output += text
            self.screen.feed(text)

    async def wait_for(self, condition, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            self._read()
            if condition():
                return
            if time.monotonic() > deadline:
                raise AssertionError(f"not seen within {timeout} s; the terminal shows:\n" + "\n".join(self.screen.lines))
            await asyncio.sleep(0.02)

    def type(self, text: bytes) -> None:
        os.write(self.fd, text)

    async def exit_status(self, timeout: float = 30.0) -> int:
        deadline = time.monotonic() + timeout
        while True:
            self._read()
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self._read()
                return os.waitstatus_to_exitcode(status)
            if time.monotonic() > deadline:
                os.kill(self.pid, signal.SIGKILL)
                raise AssertionError("softplc watch did not exit:\n" + self.output[-2000:])
            await asyncio.sleep(0.02)

    def close(self) -> None:
        try:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
        os.close(self.fd)


async def test_watch_updates_in_place_shows_forces_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    async with running_plant(tmp_path) as (runtime, server):
        terminal = Terminal("watch", "i*", "b1", "--endpoint", server.endpoint, home=tmp_path)
        try:
            await terminal.wait_for(lambda: set(terminal.screen.rows()) == {"i16", "i32", "b1"})
            assert terminal.screen.rows()["i16"][:2] == ["0", "good"]
            assert terminal.screen.lines[0].startswith(f"softplc watch: 3 tags on {server.endpoint}")
            for value in (5, 6, 7):  # changes pushed by the server, each drawn over the last
                runtime.db.submit([("i16", value)], Origin("test"))
                await terminal.wait_for(lambda: terminal.screen.rows()["i16"][0] == str(value))
            await force(runtime, "b1", True)
            await terminal.wait_for(lambda: terminal.screen.rows()["b1"][:3] == ["true", "good", "F"])
            assert "\x1b[6A" in terminal.output  # redrawn in place: back up over the 6 lines of the table…
            assert sum(line.startswith("softplc watch:") for line in terminal.screen.lines) == 1  # …not printed again below
            assert terminal.screen.rows()["i32"] == ["0", "good", terminal.screen.rows()["i32"][2]]  # not forced: no F
            terminal.type(b"\x03")  # Ctrl-C, through the terminal's line discipline
            assert await terminal.exit_status() == 0
            assert "softplc watch: interrupted (Ctrl-C)" in terminal.output
            assert "Traceback" not in terminal.output
        finally:
            terminal.close()


async def test_watch_says_when_the_server_goes_away(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO), HOME=str(tmp_path))
    async with running_plant(tmp_path) as (runtime, server):
        process = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "softplc.app.cli", "watch", "i16", "--endpoint", server.endpoint, env=env,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )
        assert process.stdout is not None and process.stderr is not None
        first = await asyncio.wait_for(process.stdout.readline(), 30)  # subscribed: the first value arrived
        assert first.decode().split("  ")[1:] == ["i16 = 0", "good\n"]  # piped: one line per change
    # The runtime has stopped (and its server with it).
    try:
        code = await asyncio.wait_for(process.wait(), 30)
    finally:
        if process.returncode is None:  # it did not notice: do not leave it running
            process.kill()
            await process.wait()
    err = (await process.stderr.read()).decode()
    assert code == 3
    assert re.fullmatch(r"softplc watch: the server went away \(.+\)\n", err), err
