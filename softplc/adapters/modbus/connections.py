"""The TCP side of the Modbus server: framing, connection cap, idle timeout, who sent a request.

pymodbus 3.16 accepts every connection and keeps a silent one open forever, so a peer can
exhaust the process's file descriptors, and thousands of chattering connections slow the
event loop the scan runs on; and one bad frame left a connection deaf for ~20 requests.
`PlcTcpServer` (a ModbusTcpServer) adds:

- **framing** (framing.py): requests are cut at their MBAP headers and answered in order; a
  header that is not Modbus TCP, or a frame still incomplete after `frame_timeout` (2 s),
  closes the connection at once, logged at most once per peer and 10 s (PeerLog).
- **max_connections**: a connection beyond the cap is accepted and at once reset (RST, no
  TIME_WAIT left behind); established connections are never disturbed by newcomers.
- **idle_timeout**: a connection that sent nothing for that long is closed (a client polling
  more often than that is never cut). 0 disables it.
- **bounded logging**: the first refusal (or idle close) of a burst is logged with the peer's
  address, then at most one line per minute with the count; never a line per connection.
- **request_peer**: while a request is served, the client's "host:port" (for the write Origin).

Idle and frame times are measured on the event loop's clock: they are about sockets, not plant time.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import struct
from collections import Counter
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.pdu import DecodePDU, ExceptionResponse
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler

from softplc.adapters.modbus.framing import MAX_FRAME, Frame, FrameBuffer, FramingError
from softplc.util.peers import PeerLog, peer_host
from softplc.util.plurals import counted

log = logging.getLogger(__name__)
REPORT_INTERVAL = 60.0
FRAME_TIMEOUT = 2.0  # s a started frame may take to arrive whole (one frame is one TCP segment in practice)
MAX_BUFFERED = 16 * MAX_FRAME  # bytes read ahead of the answers before reading pauses

# The peer ("host:port") of the connection whose request is being served; "" outside a request.
request_peer: ContextVar[str] = ContextVar("softplc_modbus_request_peer", default="")


@dataclass(frozen=True)
class ConnectionCounts:
    """What the server did with client connections since it started."""

    open: int
    refused: int
    closed_idle: int
    closed_framing: int = 0  # closed for a framing error (not a Modbus TCP frame)


class EventReport:
    """Logs the first event of a burst at once, then one line per interval with the count."""

    def __init__(self, level: int, first: str, summary: str, what: str, interval: float = REPORT_INTERVAL) -> None:
        self.level = level
        self.first = first  # formatted with the event's detail
        self.summary = summary  # formatted with the count of the events since the last line: "3 more connections"
        self.what = what  # those events, in the plural: "more connections"
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
            log.log(self.level, self.summary, counted(self._pending, self.what))
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
    """One client connection: cut into frames here, requests answered in order, closed when idle.

    pymodbus's own handler answered only the first of two requests arriving together, kept a
    bad header at the head of its buffer (answering nothing until ~500 bytes later), and ran
    each request in a task that read whichever request came last. Here the bytes go into a
    FrameBuffer, one worker task answers the complete frames one after another, and a framing
    error closes the connection.
    """

    def __init__(self, server: PlcTcpServer) -> None:
        super().__init__(server, server.trace_packet, server.trace_pdu, server.trace_connect)
        self._plc_server = server
        self.peer = ""  # "host:port", for the write Origin and the log
        self._frames = FrameBuffer()
        self._worker: asyncio.Task[None] | None = None
        self._reading_paused = False
        self._eof = False  # the client half-closed: close once its requests are answered
        self._last_heard = 0.0
        self._idle_timer: asyncio.TimerHandle | None = None
        self._frame_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        self.peer = _address(transport.get_extra_info("peername"))
        self._last_heard = self.loop.time()
        if self._plc_server.idle_timeout > 0:
            self._idle_timer = self.loop.call_later(self._plc_server.idle_timeout, self._check_idle)

    def data_received(self, data: bytes) -> None:
        self._last_heard = self.loop.time()  # one float store per read: the timer is re-armed lazily
        if self.transport is None:
            return
        self._frames.feed(data)
        if len(self._frames) > MAX_BUFFERED and not self._reading_paused:
            # A client far ahead of the answers waits in TCP's window, not in our memory.
            self._reading_paused = True
            self.transport.pause_reading()  # type: ignore[attr-defined]
        if self._worker is None:
            self._worker = self.loop.create_task(self._serve())

    def eof_received(self) -> bool:
        """The client will send nothing more: answer what it sent, then close (not before)."""
        self._eof = True
        return self._worker is not None  # True keeps the transport open until _serve is done

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_timers()
        super().connection_lost(exc)

    def close(self, reconnect: bool = False) -> None:
        self._stop_timers()
        self._frames.clear()
        super().close(reconnect)

    async def _serve(self) -> None:
        """Answer every complete frame received, in order; close the connection on a framing error."""
        request_peer.set(self.peer)  # this task's context: the adapter's write hook reads it
        try:
            while self.transport is not None:
                try:
                    frame = self._frames.next_frame()
                except FramingError as error:
                    self._framing_error(str(error), error.field)
                    return
                if frame is None:
                    break
                self._cancel_frame_timer()  # a frame completed: a timer for the next one starts afresh
                await self._answer(frame)
                if self._reading_paused and len(self._frames) <= MAX_BUFFERED // 2 and self.transport is not None:
                    self._reading_paused = False
                    self.transport.resume_reading()  # type: ignore[attr-defined]
            if self._eof:
                self.close()  # an incomplete frame after the client's EOF can never complete
            elif len(self._frames) and self._frame_timer is None and self.transport is not None:
                self._frame_timer = self.loop.call_later(self._plc_server.frame_timeout, self._partial_frame_expired)
        finally:
            self._worker = None

    async def _answer(self, frame: Frame) -> None:
        request = self._plc_server.decoder.decode(frame.pdu)  # softplc's decoder: never None for a PDU
        assert request is not None
        request.dev_id, request.transaction_id = frame.unit_id, frame.transaction_id
        try:
            response = await request.datastore_update(self._plc_server.context, frame.unit_id)
        except Exception:  # one request must not end the connection or the server
            log.exception("Modbus TCP: request from %s (function %d) failed", self.peer, request.function_code)
            response = ExceptionResponse(request.function_code, ExcCodes.DEVICE_FAILURE)
        response.transaction_id, response.dev_id = frame.transaction_id, frame.unit_id
        self._plc_server.requests[request.function_code, "exception" if isinstance(response, ExceptionResponse) else "ok"] += 1
        if self.transport is not None:  # the client may have gone while the request ran
            self.transport.write(self.framer.buildFrame(response))  # type: ignore[attr-defined]

    def _framing_error(self, reason: str, field: str) -> None:
        self._plc_server.peer_log.warning(
            peer_host(self.transport.get_extra_info("peername")), "framing errors",
            "Modbus TCP: closed the connection from %s: %s", self.peer, reason, detail=field,
        )
        self._plc_server.framing_errors += 1
        self.close()  # the answers already written are flushed before the FIN

    def _partial_frame_expired(self) -> None:
        self._frame_timer = None
        if self.transport is None or self._worker is not None or not len(self._frames):
            return
        timeout = self._plc_server.frame_timeout
        reason = f"an incomplete frame ({self._frames.describe_partial()}) for {timeout:g} s"
        self._framing_error(reason, "incomplete frame")

    def _cancel_frame_timer(self) -> None:
        if self._frame_timer is not None:
            self._frame_timer.cancel()
            self._frame_timer = None

    def _stop_timers(self) -> None:
        self._cancel_frame_timer()
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
    """ModbusTcpServer with softplc's framing and request decoder, a connection cap and an idle timeout."""

    def __init__(self, context: Any, *, address: tuple[str, int], decoder: DecodePDU, max_connections: int,
                 idle_timeout: float, frame_timeout: float = FRAME_TIMEOUT) -> None:
        super().__init__(context, address=address)
        self.decoder = decoder  # every connection decodes its requests with the server's decoder
        self.max_connections = max_connections
        self.idle_timeout = idle_timeout
        self.frame_timeout = frame_timeout
        self.peer_log = PeerLog(log, service="Modbus TCP")
        self.framing_errors = 0
        self.requests: Counter[tuple[int, str]] = Counter()  # (function code, "ok" | "exception") → answered (/metrics)
        self.refusal_report = EventReport(
            logging.WARNING,
            f"Modbus TCP: refused a connection from %s: max_connections ({max_connections}) are open",
            f"Modbus TCP: refused %s (max_connections {max_connections}) in the last {REPORT_INTERVAL:g} s",
            "more connections",
        )
        self.idle_report = EventReport(
            logging.INFO,
            f"Modbus TCP: closed the connection from %s: nothing received for {idle_timeout:g} s (idle_timeout)",
            f"Modbus TCP: closed %s in the last {REPORT_INTERVAL:g} s",
            "more idle connections",
        )

    @property
    def counts(self) -> ConnectionCounts:
        return ConnectionCounts(len(self.active_connections), self.refusal_report.total, self.idle_report.total,
                                self.framing_errors)

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
    """'host:port' of a socket peer name ('[::1]:port' for IPv6)."""
    if isinstance(peer, tuple) and len(peer) >= 2:
        host = f"[{peer[0]}]" if ":" in str(peer[0]) else peer[0]
        return f"{host}:{peer[1]}"
    return str(peer)
