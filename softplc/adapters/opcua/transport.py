"""The network side of the server, hardened: asyncua's binary server with stricter framing and limits.

asyncua 2.1.0 (pinned) leaves gaps this module closes, by subclassing its server classes
(gaps in how requests are served are closed by processor.py):

- A frame header may announce any size, and the receive buffer grows (quadratically copied)
  until that many bytes arrived. `GuardedProtocol` closes a connection whose frame is bigger
  than the receive buffer agreed in the Hello/Acknowledge, or whose type is not an OPC UA one,
  after sending an ERR message, so junk costs nothing and logs one line.
- asyncua accepts messages of 100 MB in 1601 chunks from anyone, before any login. Here a
  message (all its chunks) may have `max_message_size` bytes (4 MB) and `max_chunk_count`
  chunks once a session is activated, and only 64 KB before: an oversized message closes the
  connection with an ERR message (BadRequestTooLarge) as soon as its size is known. A
  connection that has 1 MB of received requests waiting stops being read until they are
  processed (TCP pushes back on the client), so memory per connection stays bounded.
- One IP address may hold at most `max_connections_per_peer` connections (asyncua only caps
  the total, at 1000). Refused and idle-closed connections are logged through `PeerLog`: a
  flood writes one line per peer and 10 s, not one per connection.
- A request for a security policy the server does not offer is answered with an ERR message
  and the connection closed.
- The certificate of each secured channel is noted (`TrackingPolicyFactory`), so the client
  certificate check knows a secured session from one on a None channel.

Requests bigger than 1 KB, and every subscription publish, also wait for `ScanGuard` (see
scheduling.py) so they never delay the start of a scan cycle.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from dataclasses import dataclass
from typing import Any

from asyncua import Server, ua
from asyncua.common.connection import TransportLimits
from asyncua.common.utils import Buffer
from asyncua.crypto import uacrypto
from asyncua.crypto.security_policies import SecurityPolicyNone
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol
from asyncua.ua.ua_binary import header_from_binary, uatcp_to_binary

from softplc.adapters.opcua.methods import CheckedMethodService
from softplc.adapters.opcua.processor import DiscoveryOnlyNone, GuardedProcessor, PolicyRefused
from softplc.adapters.opcua.scheduling import ScanGuard
from softplc.adapters.opcua.settings import (
    DEFAULT_MAX_CHUNK_COUNT,
    DEFAULT_MAX_CONNECTIONS_PER_PEER,
    DEFAULT_MAX_MESSAGE_SIZE,
)
from softplc.adapters.opcua.subscriptions import GuardedSubscriptionService
from softplc.security.certificates import SecuredChannels
from softplc.util.peers import PeerLog, peer_host

log = logging.getLogger(__name__)

_MESSAGE_TYPES = frozenset({b"HEL", b"ACK", b"ERR", b"OPN", b"CLO", b"MSG", b"RHE"})
_CHUNK_TYPES = frozenset({b"F", b"C", b"A"})
_SECURE_TYPES = frozenset({b"OPN", b"CLO", b"MSG"})  # secure conversation: may come in chunks
GUARDED_REQUEST_BYTES = 1024
PRE_SESSION_MESSAGE_BYTES = 64 * 1024  # largest message before a session is activated
PAUSE_READING_BYTES = 1024 * 1024  # received but unprocessed bytes at which a connection stops being read
LINGER_SECONDS = 1.0  # after an ERR message, how long what the peer still sends is read and dropped
_BUFFER_BYTES = 65535  # receive and send buffer (chunk size) offered in the Acknowledge


@dataclass(frozen=True)
class ConnectionLimits:
    """What one client connection may send and how many one peer address may hold."""

    max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE
    max_chunk_count: int = DEFAULT_MAX_CHUNK_COUNT
    max_connections_per_peer: int = DEFAULT_MAX_CONNECTIONS_PER_PEER
    pre_session_message_size: int = PRE_SESSION_MESSAGE_BYTES

    def transport_limits(self) -> TransportLimits:
        """asyncua's limits, advertised in the Acknowledge and checked again by its SecureConnection."""
        return TransportLimits(max_recv_buffer=_BUFFER_BYTES, max_send_buffer=_BUFFER_BYTES,
                               max_chunk_count=self.max_chunk_count, max_message_size=self.max_message_size)


class TrackingPolicyFactory:
    """Wraps asyncua's SecurityPolicyFactory to note the certificate of every secured channel."""

    def __init__(self, inner: Any, secured: SecuredChannels) -> None:
        self._inner = inner
        self._secured = secured
        self._is_secure = inner.cls is not SecurityPolicyNone

    def matches(self, uri: str, mode: ua.MessageSecurityMode | None = None) -> bool:
        return self._inner.matches(uri, mode)

    def create(self, peer_certificate: bytes | None) -> Any:
        if self._is_secure:
            self._secured.add(peer_certificate)
        return self._inner.create(peer_certificate)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


class GuardedProtocol(OPCUAProtocol):
    """One client connection: refuses oversized or non-OPC UA frames and messages before
    buffering them, bounds connections per peer, and processes a big request only when no
    scan cycle is about to start."""

    guard: ScanGuard = ScanGuard()
    connection_limits: ConnectionLimits = ConnectionLimits()
    peer_log: PeerLog = PeerLog(log)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.peer_name = transport.get_extra_info("peername")
        self.peer = peer_host(self.peer_name)
        self._message_bytes = self._message_chunks = 0  # of the message being received
        self._queued_bytes = 0  # received, not yet processed
        self._reading_paused = False
        self._refused = False  # an ERR message was sent: the connection is closing
        if len(self.clients) >= self.iserver.max_connections:
            self._turn_away(transport, f"the server has {len(self.clients)} connections (its limit)")
            return
        same_peer = sum(1 for client in self.clients if getattr(client, "peer", None) == self.peer)
        if same_peer >= self.connection_limits.max_connections_per_peer:
            self._turn_away(transport, f"{same_peer} connections open from it (max_connections_per_peer)")
            return
        # As OPCUAProtocol.connection_made (asyncua 2.1.0), with our processor and no log line.
        self.transport = transport  # type: ignore[assignment]
        self.processor = GuardedProcessor(self.iserver, self.transport, self.limits)
        self.processor.set_policies(self.policies)
        self.iserver.asyncio_transports.append(transport)
        self.clients.append(self)
        self._task = asyncio.create_task(self._process_received_message_loop())
        if self.iserver.max_pending_activation_seconds > 0:
            self._activation_watchdog_task = asyncio.create_task(self._activation_watchdog())

    def _turn_away(self, transport: asyncio.BaseTransport, reason: str) -> None:
        self.peer_log.warning(self.peer, "refused connections", "OPC UA: refusing a connection from %s: %s", self.peer, reason)
        error = ua.ErrorMessage(ua.StatusCode(ua.StatusCodes.BadTcpNotEnoughResources), "too many connections")
        transport.write(uatcp_to_binary(ua.MessageType.Error, error))  # type: ignore[attr-defined]
        transport.close()

    async def _activation_watchdog(self) -> None:
        # As asyncua's, logging through peer_log: a flood of idle connections writes one line.
        try:
            await asyncio.sleep(self.iserver.max_pending_activation_seconds)
            session = self.processor.session if self.processor is not None else None
            if session is None or not session.is_activated():
                self.peer_log.warning(self.peer, "idle connections closed", "OPC UA: closing a connection from %s: "
                                      "no session activated within %.0f s", self.peer, self.iserver.max_pending_activation_seconds)
                if self.transport is not None:
                    self.transport.close()
        except asyncio.CancelledError:
            pass

    def data_received(self, data: bytes) -> None:
        # Framing as OPCUAProtocol.data_received, checking each frame header as soon as it
        # arrived (a bogus size never makes the buffer grow) and each message's running size.
        if self.transport is None or self.transport.is_closing() or self._refused:
            return
        self._buffer += data
        while len(self._buffer) >= 8:
            message_type, chunk_type, size = struct.unpack_from("<3scI", self._buffer)
            if not self._acceptable(message_type, chunk_type, size):
                return
            if len(self._buffer) < size:
                return
            frame, self._buffer = self._buffer[:size], self._buffer[size:]
            if message_type in _SECURE_TYPES and not self._within_message_limits(chunk_type, size):
                return
            buffer = Buffer(frame)
            header = header_from_binary(buffer)
            try:
                self.messages.put_nowait((header, buffer))
            except asyncio.QueueFull:
                self._refuse(ua.StatusCodes.BadTcpNotEnoughResources, f"more than {self.messages.maxsize} requests waiting")
                return
            self._queued_bytes += size
        if self._queued_bytes > PAUSE_READING_BYTES and not self._reading_paused:
            self._reading_paused = True
            self.transport.pause_reading()

    def _acceptable(self, message_type: bytes, chunk_type: bytes, size: int) -> bool:
        limit = max(self.limits.max_recv_buffer, 8192)
        if message_type not in _MESSAGE_TYPES or chunk_type not in _CHUNK_TYPES:
            self._refuse(ua.StatusCodes.BadTcpMessageTypeInvalid, f"not an OPC UA frame (type {message_type!r})")
            return False
        smallest = (12 if message_type in _SECURE_TYPES else 8) + 1  # header (+ secure channel id) and a body
        if size < smallest or size > limit:
            self._refuse(ua.StatusCodes.BadTcpMessageTooLarge, f"frame of {size} bytes (limit {limit})")
            return False
        return True

    def _within_message_limits(self, chunk_type: bytes, size: int) -> bool:
        """Count a secure conversation chunk into its message; refuse a message over the limits."""
        session = self.processor.session if self.processor is not None else None
        activated = session is not None and session.is_activated()
        limits = self.connection_limits
        most_bytes = limits.max_message_size if activated else limits.pre_session_message_size
        self._message_bytes += size
        self._message_chunks += 1
        if self._message_bytes > most_bytes or self._message_chunks > limits.max_chunk_count:
            when = "" if activated else " before a session is activated"
            self._refuse(ua.StatusCodes.BadRequestTooLarge, f"message of more than {most_bytes} bytes or "
                         f"{limits.max_chunk_count} chunks{when}")
            return False
        if chunk_type != b"C":  # final (or aborted): the next chunk starts a new message
            self._message_bytes = self._message_chunks = 0
        return True

    async def _process_one_msg(self, header: Any, buf: Any) -> bool:
        if self._refused:
            return False  # requests that arrived before the refusal are dropped with it
        try:
            # Small requests (a Write of a few tags, a Publish) cost well under a millisecond:
            # served at once, so a client's write still lands before an imminent cycle. Bigger
            # ones (a Read or Write of many nodes) wait until the cycle has started.
            if header.body_size > GUARDED_REQUEST_BYTES:
                await self.guard.clear()
            try:
                return await super()._process_one_msg(header, buf)
            except PolicyRefused as refused:
                self._refuse(ua.StatusCodes.BadSecurityPolicyRejected, str(refused))
                return False
        finally:
            self._queued_bytes -= header.header_size + header.body_size
            if self._reading_paused and self._queued_bytes <= PAUSE_READING_BYTES // 4 and self.transport is not None \
                    and not self.transport.is_closing():
                self._reading_paused = False
                self.transport.resume_reading()

    def _refuse(self, code: int, reason: str) -> None:
        """Send an ERR message and close: stop reading requests at once, but keep draining what the
        peer still sends for a moment, so the ERR reaches it instead of being lost in a TCP reset."""
        self.peer_log.warning(self.peer, "connections closed for bad requests", "OPC UA: closing connection from %s: %s",
                              self.peer_name, reason, detail=ua.StatusCode(code).name)
        self._buffer = b""
        self._refused = True
        transport = self.transport
        if transport is None or transport.is_closing():
            return
        error = ua.ErrorMessage(ua.StatusCode(code), reason)
        transport.write(uatcp_to_binary(ua.MessageType.Error, error))
        if transport.can_write_eof():
            transport.write_eof()
            if self._reading_paused:
                self._reading_paused = False
                transport.resume_reading()
            asyncio.get_running_loop().call_later(LINGER_SECONDS, transport.close)
        else:
            transport.close()


class GuardedBinaryServer(BinaryServer):
    guard: ScanGuard = ScanGuard()
    connection_limits: ConnectionLimits = ConnectionLimits()
    peer_log: PeerLog = PeerLog(log)

    def _make_protocol(self) -> OPCUAProtocol:
        protocol = GuardedProtocol(
            iserver=self.iserver,
            policies=self._policies,
            clients=self.clients,
            closing_tasks=self.closing_tasks,
            limits=self.limits,
        )
        protocol.guard = self.guard
        protocol.connection_limits = self.connection_limits
        protocol.peer_log = self.peer_log
        return protocol


class GuardedServer(Server):
    """asyncua's Server, listening through GuardedBinaryServer with tracked/refused policies."""

    def __init__(self, *args: Any, secured: SecuredChannels, offer_none: bool, guard: ScanGuard,
                 connection_limits: ConnectionLimits | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.secured = secured
        self.offer_none = offer_none
        self.guard = guard
        self.connection_limits = connection_limits or ConnectionLimits()
        self.limits = self.connection_limits.transport_limits()
        # Subscriptions that publish clear of the scan; set before init() so every user of the
        # service (sessions, condition refresh) gets this one.
        service = GuardedSubscriptionService(self.iserver.aspace, iserver=self.iserver, guard=guard)
        self.iserver.subscription_service = service
        self.iserver.isession.subscription_service = service
        # Call with Part 4's statuses for unknown objects and methods.
        self.iserver.method_service.stop()
        self.iserver.method_service = CheckedMethodService(self.iserver.aspace)

    async def start(self) -> None:
        # Server.start of asyncua 2.1.0, with our binary server and policy wrappers.
        if self.iserver.certificate is not None:
            uacrypto.check_certificate(self.iserver.certificate, self._application_uri, self.endpoint.hostname)
        await self._setup_server_nodes()
        policies: list[Any] = [TrackingPolicyFactory(factory, self.secured) for factory in self._policies]
        if not self.offer_none:
            policies.append(DiscoveryOnlyNone())
        self._policies = policies
        await self.iserver.start()
        try:
            host, port = self._get_bind_socket_info()
            self.bserver = GuardedBinaryServer(self.iserver, host, port, self.limits)  # type: ignore[arg-type]
            self.bserver.guard = self.guard
            self.bserver.connection_limits = self.connection_limits
            self.bserver.peer_log = PeerLog(log)
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            await self.iserver.stop()
            raise
