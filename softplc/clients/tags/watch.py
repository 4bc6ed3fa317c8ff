"""`softplc watch PATTERN...`: a table of tag values that updates in place, fed by an OPC UA subscription.

The server pushes each change (sampling interval 0, queue 1); the table is redrawn at most
`MAX_REDRAWS` times a second, whatever the rate of changes, by moving the cursor back to the
table's first line and rewriting every line. When the output is not a terminal (a pipe, a
file), each change is printed as one line instead. The watch ends on Ctrl-C (or SIGTERM) and
when the server goes away, which it says.
"""

from __future__ import annotations

import asyncio
import os
import shutil
import signal
from collections.abc import Callable
from typing import Any, TextIO

from asyncua import Client, ua

from softplc.clients.session import LiveSession, Reading
from softplc.clients.tags.table import READING_HEADER, reading_row, table_lines

SERVICE_LEVEL = ua.NodeId(ua.ObjectIds.Server_ServiceLevel)
HEALTHY = 200  # a redundant pair's active serves ServiceLevel 200-255
MAX_REDRAWS = 10  # per second: a terminal cannot show more, and a fast task must not flood it
CURSOR_UP = "\x1b[{}A"
CLEAR_LINE_END = "\x1b[K"


class WatchEnded(Exception):
    """The watch stopped because the server went away; the message says so."""


class WatchTable:
    """The latest reading of every watched tag, and the screen lines that show them."""

    def __init__(self, tags: list[str], title: str) -> None:
        self.tags = tags
        self.title = title
        self.readings: dict[str, Reading | None] = dict.fromkeys(tags)
        self.changes = 0

    def update(self, reading: Reading) -> None:
        if reading.tag in self.readings:
            self.readings[reading.tag] = reading
            self.changes += 1

    def lines(self, width: int, height: int) -> list[str]:
        """The screen: title, header, one line per tag (as many as fit), each cut to the width."""
        rows = [reading_row(self.readings[tag], tag) for tag in self.tags]
        room = max(height - 4, 1)  # title, header, rule, and the line the cursor rests on
        hidden = len(rows) - room if len(rows) > room else 0
        lines = [self.title] + table_lines(rows[: len(rows) - hidden] if hidden else rows, READING_HEADER)
        if hidden:
            lines[-1] = f"… and {hidden + 1} more tags: make the terminal taller or the patterns narrower"
        return [line[: max(width - 1, 10)] for line in lines]


class _Subscriber:
    """asyncua's subscription handler: notes each change and a lost subscription."""

    def __init__(self, table: WatchTable, changed: asyncio.Event, lost: Callable[[str], None]) -> None:
        self.table = table
        self.changed = changed
        self.lost = lost
        self.on_change: Callable[[Reading], None] | None = None

    def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
        if node.nodeid == SERVICE_LEVEL:  # following the active of a redundant pair
            if isinstance(value, int) and value < HEALTHY:
                self.lost(f"it is no longer the active one (ServiceLevel {value})")
            return
        reading = Reading.from_data_value(node.nodeid.Identifier, data.monitored_item.Value)
        self.table.update(reading)
        if self.on_change is not None:
            self.on_change(reading)
        self.changed.set()

    def status_change_notification(self, status: ua.StatusChangeNotification) -> None:
        self.lost(f"the subscription ended: {ua.StatusCode(status.Status.value).name}")


async def watch(session: LiveSession, tags: list[str], out: TextIO, *, endpoint: str, interval_ms: float = 100.0,
                tty: bool | None = None, follow: bool = False) -> str:
    """Show the tags until Ctrl-C (returns why it stopped) or until the server goes away (raises WatchEnded).

    `follow`: the server is a member of a redundant pair; it also "goes away" when it stops being
    the active one (its ServiceLevel drops below 200), so the caller can follow the new active.
    """
    client: Client = session.client
    tty = out.isatty() if tty is None else tty
    table = WatchTable(tags, f"softplc watch: {len(tags)} tag{'s' if len(tags) != 1 else ''} on {endpoint} — Ctrl-C to stop")
    changed, done = asyncio.Event(), asyncio.Event()
    reasons: list[str] = []

    def finish(reason: str) -> None:
        if not done.is_set():
            reasons.append(reason)
            done.set()

    async def connection_lost(error: Exception) -> None:
        finish(f"the server went away ({_describe(error)})")

    client.connection_lost_callback = connection_lost
    loop = asyncio.get_running_loop()
    for number, name in ((signal.SIGINT, "interrupted (Ctrl-C)"), (signal.SIGTERM, "terminated (SIGTERM)")):
        loop.add_signal_handler(number, finish, name)
    subscriber = _Subscriber(table, changed, lambda why: finish(f"the server went away ({why})"))
    if not tty:
        subscriber.on_change = lambda reading: _print_change(reading, out)
    try:
        subscription = await client.create_subscription(interval_ms, subscriber)
        nodes = [client.get_node(session.node_id(tag)) for tag in tags] + ([client.get_node(SERVICE_LEVEL)] if follow else [])
        await subscription.subscribe_data_change(nodes, queuesize=1, sampling_interval=0)
        drawn = 0
        while not done.is_set():
            await _first(changed, done)
            changed.clear()
            if tty and not done.is_set():
                drawn = _draw(table, out, drawn)
                await _first(done, timeout=1.0 / MAX_REDRAWS)
        if tty:
            _draw(table, out, drawn)
    finally:
        for number in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(number)
        client.connection_lost_callback = None
    reason = reasons[0]
    if reason.startswith("the server went away"):
        raise WatchEnded(reason)
    return reason


def _draw(table: WatchTable, out: TextIO, drawn: int) -> int:
    """Rewrite the table over its previous drawing (`drawn` lines); returns how many lines it has now."""
    size = shutil.get_terminal_size((100, 40)) if out.isatty() else os.terminal_size((100, 40))
    lines = table.lines(size.columns, size.lines)
    text = (CURSOR_UP.format(drawn) + "\r") if drawn else ""
    text += "".join(line + CLEAR_LINE_END + "\n" for line in lines)
    out.write(text)
    out.flush()
    return len(lines)


def _print_change(reading: Reading, out: TextIO) -> None:
    """One line per change, for a pipe or a file: `2026-11-24 10:49:03.123  t01_iBL = 42.5  good  F`."""
    tag, value, quality, forced, stamp = reading_row(reading, reading.tag)
    print(f"{stamp}  {tag} = {value}  {quality}" + (f"  {forced}" if forced else ""), file=out, flush=True)


async def _first(*events: asyncio.Event, timeout: float | None = None) -> None:
    """Wait until one of the events is set (or the timeout passes)."""
    waiters = [asyncio.ensure_future(event.wait()) for event in events]
    try:
        await asyncio.wait(waiters, timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for waiter in waiters:
            waiter.cancel()


def _describe(error: BaseException) -> str:
    if isinstance(error, ua.UaStatusCodeError):
        return ua.StatusCode(error.code).name
    return str(error) or type(error).__name__

