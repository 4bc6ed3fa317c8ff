"""The network side of the server, hardened: asyncua's binary server with stricter framing and policies.

asyncua 2.1.0 (pinned) leaves gaps this module closes, by subclassing its server classes:

- A client may use a SecurityPolicy None channel for sessions even when None is not offered
  (the channel falls back to asyncua's initial None policy). Here a None channel that was not
  offered serves discovery only (GetEndpoints, FindServers: what every client needs before it
  opens a secured channel); any other request on it gets BadSecurityPolicyRejected. A request
  for a policy the server does not know is answered with an ERR message and the connection closed.
- A frame header may announce any size, and the receive buffer grows (quadratically copied)
  until that many bytes arrived. `GuardedProtocol` closes a connection whose frame is bigger
  than the receive buffer agreed in the Hello/Acknowledge, or whose type is not an OPC UA one,
  after sending an ERR message, so junk costs nothing and logs one line.
- RegisterServer needs no session in asyncua: anyone could add entries to FindServers. We are
  not a discovery server, so it is refused (BadServiceUnsupported).
- The certificate of each secured channel is noted (`TrackingPolicyFactory`), so the client
  certificate check knows a secured session from one on a None channel.

Requests bigger than 1 KB, and every subscription publish, also wait for `ScanGuard` (see
scheduling.py) so they never delay the start of a scan cycle.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from typing import Any

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.crypto import uacrypto
from asyncua.crypto.security_policies import SecurityPolicyNone
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua.ua_binary import uatcp_to_binary

from softplc.opcua.scheduling import ScanGuard
from softplc.opcua.subscriptions import GuardedSubscriptionService
from softplc.opcua.security import SecuredChannels

log = logging.getLogger(__name__)

_MESSAGE_TYPES = frozenset({b"HEL", b"ACK", b"ERR", b"OPN", b"CLO", b"MSG", b"RHE"})
_CHUNK_TYPES = frozenset({b"F", b"C", b"A"})
GUARDED_REQUEST_BYTES = 1024


class PolicyRefused(Exception):
    """A client asked for a security policy the server does not offer."""


_DISCOVERY = frozenset(ua.NodeId(type_id) for type_id in (
    ua.ObjectIds.GetEndpointsRequest_Encoding_DefaultBinary,
    ua.ObjectIds.FindServersRequest_Encoding_DefaultBinary,
    ua.ObjectIds.FindServersOnNetworkRequest_Encoding_DefaultBinary,
    ua.ObjectIds.CloseSecureChannelRequest_Encoding_DefaultBinary,
))


_REGISTRATION = frozenset(ua.NodeId(type_id) for type_id in (
    ua.ObjectIds.RegisterServerRequest_Encoding_DefaultBinary,
    ua.ObjectIds.RegisterServer2Request_Encoding_DefaultBinary,
))


class DiscoveryOnlyPolicy(SecurityPolicyNone):
    """SecurityPolicy None for a channel that may only discover endpoints."""

    discovery_only = True


class DiscoveryOnlyNone:
    """Stands in for SecurityPolicy None when it is not offered for sessions."""

    def matches(self, uri: str, mode: ua.MessageSecurityMode | None = None) -> bool:
        return uri == SecurityPolicyNone.URI

    def create(self, peer_certificate: bytes | None) -> SecurityPolicyNone:
        return DiscoveryOnlyPolicy(peer_certificate)


class GuardedProcessor(UaProcessor):
    """asyncua's message processor, with the discovery-only None channel and clean policy refusals."""

    def open_secure_channel(self, algohdr: Any, seqhdr: Any, body: Any) -> None:
        try:
            super().open_secure_channel(algohdr, seqhdr, body)
        except ua.UaError as error:
            raise PolicyRefused(str(error)) from None

    async def _process_message(self, typeid: ua.NodeId, requesthdr: Any, seqhdr: Any, body: Any) -> Any:
        if getattr(self._connection.security_policy, "discovery_only", False) and typeid not in _DISCOVERY:
            raise ServiceError(ua.StatusCodes.BadSecurityPolicyRejected)
        if typeid in _REGISTRATION:  # we are no discovery server; asyncua would accept them without a session
            raise ServiceError(ua.StatusCodes.BadServiceUnsupported)
        return await super()._process_message(typeid, requesthdr, seqhdr, body)


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
    """One client connection: refuses oversized or non-OPC UA frames before buffering them,
    and processes a big request only when no scan cycle is about to start."""

    guard: ScanGuard = ScanGuard()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        if self.processor is not None:
            # Same as OPCUAProtocol.connection_made, with our processor.
            self.processor = GuardedProcessor(self.iserver, self.transport, self.limits)
            self.processor.set_policies(self.policies)

    def data_received(self, data: bytes) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        head = self._buffer[:8] if len(self._buffer) >= 8 else (self._buffer + data[:8])[:8]
        if len(head) == 8 and not self._acceptable(head):
            return
        super().data_received(data)
        # What is left is the start of an incomplete frame: check its header now, so a bogus
        # size never makes the buffer grow.
        if self.transport is not None and not self.transport.is_closing() and len(self._buffer) >= 8:
            self._acceptable(self._buffer[:8])

    def _acceptable(self, head: bytes) -> bool:
        message_type, chunk_type, size = struct.unpack("<3scI", head)
        limit = max(self.limits.max_recv_buffer, 8192)
        if message_type not in _MESSAGE_TYPES or chunk_type not in _CHUNK_TYPES:
            self._refuse(ua.StatusCodes.BadTcpMessageTypeInvalid, f"not an OPC UA frame (type {message_type!r})")
            return False
        if size < 8 or size > limit:
            self._refuse(ua.StatusCodes.BadTcpMessageTooLarge, f"frame of {size} bytes (limit {limit})")
            return False
        return True

    async def _process_one_msg(self, header: Any, buf: Any) -> bool:
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

    def _refuse(self, code: int, reason: str) -> None:
        log.warning("OPC UA: closing connection from %s: %s", self.peer_name, reason)
        self._buffer = b""
        if self.transport is not None and not self.transport.is_closing():
            error = ua.ErrorMessage(ua.StatusCode(code), reason)
            self.transport.write(uatcp_to_binary(ua.MessageType.Error, error))
            self.transport.close()


class GuardedBinaryServer(BinaryServer):
    guard: ScanGuard = ScanGuard()

    def _make_protocol(self) -> OPCUAProtocol:
        protocol = GuardedProtocol(
            iserver=self.iserver,
            policies=self._policies,
            clients=self.clients,
            closing_tasks=self.closing_tasks,
            limits=self.limits,
        )
        protocol.guard = self.guard
        return protocol


class GuardedServer(Server):
    """asyncua's Server, listening through GuardedBinaryServer with tracked/refused policies."""

    def __init__(self, *args: Any, secured: SecuredChannels, offer_none: bool, guard: ScanGuard, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.secured = secured
        self.offer_none = offer_none
        self.guard = guard
        # Subscriptions that publish clear of the scan; set before init() so every user of the
        # service (sessions, condition refresh) gets this one.
        service = GuardedSubscriptionService(self.iserver.aspace, iserver=self.iserver, guard=guard)
        self.iserver.subscription_service = service
        self.iserver.isession.subscription_service = service

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
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            await self.iserver.stop()
            raise
