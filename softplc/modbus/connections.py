"""The TCP side of the Modbus server: a cap on simultaneous connections and an idle timeout.

pymodbus 3.16 accepts every connection and keeps a silent one open forever, so a peer can
exhaust the process's file descriptors, and thousands of chattering connections slow the
event loop the scan runs on. `PlcTcpServer` (a ModbusTcpServer) adds:

- **max_connections**: a connection beyond the cap is accepted and at once reset (RST, no
  TIME_WAIT left behind); established connections are never disturbed by newcomers.
- **idle_timeout**: a connection that sent nothing for that long is closed (a client polling
  more often than that is never cut). 0 disables it.
- **bounded logging**: the first refusal (or idle close) of a burst is logged with the peer's
  address, then at most one line per minute with the count; never a line per connection.

Idle time is measured on the event loop's clock: it is about sockets, not plant time.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import struct
from dataclasses import dataclass
from typing import Any

from pymodbus.pdu import DecodePDU
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler

log = logging.getLogger(__name__)
REPORT_INTERVAL = 60.0


@dataclass(frozen=True)
class ConnectionCounts:
    """What the server did with client connections since it started."""

    open: int
    refused: int
    closed_idle: int


class EventReport:
    """Logs the first event of a burst at once, then one line per interval with the count."""

    def __init__(self, level: int, first: str, summary: str, interval: float = REPORT_INTERVAL) -> None:
        self.level = level
        self.first = first  # formatted with the event's detail
        self.summary = summary  # formatted with the number of events since the last line
        self.interval = interval
        self.total = 0
        self._pending = 0
        self._timer: asyncio.TimerHandle | None = None

    def note(self, detail: Any) -> None:
        self.total += 1
        if self._timer is None:
            log.log(self.level, self.first, detail)
            self._timer = asyncio.get_running_loop().call_later(self.interval, self._tick)
        else:
            self._pending += 1

    def close(self) -> None:
        """Stop the timer and log what is still pending."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._flush()

    def _tick(self) -> None:
        self._timer = None
        if self._pending:
            self._flush()
            self._timer = asyncio.get_running_loop().call_later(self.interval, self._tick)

    def _flush(self) -> None:
        if self._pending:
            log.log(self.level, self.summary, self._pending)
            self._pending = 0


class _Refused(asyncio.Protocol):
    """Protocol of a connection beyond the cap: reset it as soon as it exists."""

    def __init__(self, report: EventReport) -> None:
        self._report = report

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        sock = transport.get_extra_info("socket")
        if sock is not None:
            # Linger 0: close with RST, so no TIME_WAIT state piles up on our side in a flood.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        peer = transport.get_extra_info("peername")
        transport.abort()
        self._report.note(_address(peer))


class _Connection(ServerRequestHandler):
    """pymodbus's per-connection handler, closed after `idle_timeout` seconds without data."""

    def __init__(self, server: PlcTcpServer) -> None:
        super().__init__(server, server.trace_packet, server.trace_pdu, server.trace_connect)
        self._plc_server = server
        self._last_heard = 0.0
        self._idle_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        self._last_heard = self.loop.time()
        if self._plc_server.idle_timeout > 0:
            self._idle_timer = self.loop.call_later(self._plc_server.idle_timeout, self._check_idle)

    def data_received(self, data: bytes) -> None:
        self._last_heard = self.loop.time()  # one float store per read: the timer is re-armed lazily
        super().data_received(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_timer()
        super().connection_lost(exc)

    def close(self, reconnect: bool = False) -> None:
        self._stop_timer()
        super().close(reconnect)

    def _stop_timer(self) -> None:
        if self._idle_timer is not None:
            self._idle_timer.cancel()
            self._idle_timer = None

    def _check_idle(self) -> None:
        self._idle_timer = None
        transport = self.transport
        if transport is None:
            return
        timeout = self._plc_server.idle_timeout
        silent = self.loop.time() - self._last_heard
        if silent < timeout:
            self._idle_timer = self.loop.call_later(timeout - silent, self._check_idle)
            return
        peer = transport.get_extra_info("peername")
        self.close()  # pymodbus closes the transport and forgets the connection
        if isinstance(transport, asyncio.WriteTransport) and transport.get_write_buffer_size():
            transport.abort()  # a peer that does not read would keep a graceful close pending
        self._plc_server.idle_report.note(_address(peer))


class PlcTcpServer(ModbusTcpServer):
    """ModbusTcpServer with softplc's request decoder, a connection cap and an idle timeout."""

    def __init__(self, context: Any, *, address: tuple[str, int], decoder: DecodePDU, max_connections: int, idle_timeout: float) -> None:
        super().__init__(context, address=address)
        self.decoder = decoder  # every connection's framer decodes with the server's decoder
        self.max_connections = max_connections
        self.idle_timeout = idle_timeout
        self.refusal_report = EventReport(
            logging.WARNING,
            f"Modbus TCP: refused a connection from %s: max_connections ({max_connections}) are open",
            f"Modbus TCP: refused %d more connections (max_connections {max_connections}) in the last {REPORT_INTERVAL:g} s",
        )
        self.idle_report = EventReport(
            logging.INFO,
            f"Modbus TCP: closed the connection from %s: nothing received for {idle_timeout:g} s (idle_timeout)",
            f"Modbus TCP: closed %d more idle connections in the last {REPORT_INTERVAL:g} s",
        )

    @property
    def counts(self) -> ConnectionCounts:
        return ConnectionCounts(len(self.active_connections), self.refusal_report.total, self.idle_report.total)

    def handle_new_connection(self) -> Any:
        """asyncio's protocol factory for each accepted socket: refuse beyond the cap."""
        if len(self.active_connections) >= self.max_connections:
            return _Refused(self.refusal_report)
        return super().handle_new_connection()

    def callback_new_connection(self) -> ServerRequestHandler:
        return _Connection(self)

    async def shutdown(self) -> None:
        await super().shutdown()
        self.refusal_report.close()
        self.idle_report.close()


def _address(peer: Any) -> str:
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"{peer[0]}:{peer[1]}"
    return str(peer)
