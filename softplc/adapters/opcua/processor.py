"""How requests are served: asyncua's UaProcessor with the gaps of asyncua 2.1.0 (pinned) closed.

- A client may use a SecurityPolicy None channel for sessions even when None is not offered
  (the channel falls back to asyncua's initial None policy). Here a None channel that was not
  offered serves discovery only (GetEndpoints, FindServers: what every client needs before it
  opens a secured channel); any other request on it gets BadSecurityPolicyRejected.
- asyncua checks the client certificate of a session only if CreateSession carries one: a
  client that opened a Sign/SignAndEncrypt channel with an untrusted certificate and left it
  out of CreateSession got a session. Here the channel's certificate is always checked, and a
  different one in CreateSession is refused (BadCertificateInvalid).
- RegisterServer needs no session in asyncua: anyone could add entries to FindServers. We are
  not a discovery server, so it is refused (BadServiceUnsupported).
- asyncua checks a password synchronously on the event loop. A UserName login is decided here
  first, off the loop and throttled (logins.py); a refused one is answered here
  (BadUserAccessDenied), without asyncua's error line.
- asyncua ignores RequestedMaxReferencesPerNode and has no BrowseNext: Browse and BrowseNext
  are served here with continuation points (browsing.py).
- The session's user learns the client's address once its session is activated (writes carry
  it in their `Origin`, for the audit trail).
- Read and Write, the services clients call most, are served here first: asyncua finds a
  service by comparing the request's type with a freshly built NodeId per service in turn (17 for
  a Write, ~15 µs of a Write's ~100 µs here); the service itself is asyncua's.
- Publish, Write and Read responses are encoded by `response_encoding.encode_response` (a tag
  change's value encoded once for every subscriber and Read; asyncua's generic encoder, which
  runs cold on a sparse path, for the rest: protocols/opcua_binary.py).
- A session whose connection is lost keeps its subscriptions until it times out (asyncua, Part
  4: the client may come back with ActivateSession on a new connection); they go dormant at
  once, so a vanished client costs no work per tag change meanwhile (subscriptions.py). A
  connection whose session timed out while it stayed open (a hung client, a cable pulled without
  a TCP reset) is closed; asyncua left it open for good.
"""

from __future__ import annotations

import time
from typing import Any

from asyncua import ua
from asyncua.common.utils import Buffer, ServiceError
from asyncua.crypto.security_policies import SecurityPolicyNone
from asyncua.server.internal_session import SessionState
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua.ua_binary import struct_from_binary
from cryptography import x509

from softplc.adapters.opcua.browsing import ContinuationPoints
from softplc.adapters.opcua.response_encoding import encode_response
from softplc.adapters.opcua.roles import SessionUser
from softplc.adapters.opcua.subscriptions import GuardedSubscriptionService
from softplc.util.peers import peer_host


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


_CREATE_SESSION = ua.NodeId(ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary)
_ACTIVATE_SESSION = ua.NodeId(ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary)
_BROWSE = ua.NodeId(ua.ObjectIds.BrowseRequest_Encoding_DefaultBinary)
_BROWSE_NEXT = ua.NodeId(ua.ObjectIds.BrowseNextRequest_Encoding_DefaultBinary)
_READ = ua.NodeId(ua.ObjectIds.ReadRequest_Encoding_DefaultBinary)
_WRITE = ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)


class GuardedProcessor(UaProcessor):
    """asyncua's message processor, with the discovery-only None channel, clean policy refusals,
    password logins decided off the event loop, and Browse continuation points."""

    _continuation_points: ContinuationPoints | None = None
    _continuation_session: Any = None

    def send_response(self, requesthandle: int, seqhdr: Any, response: Any,
                      msgtype: ua.MessageType = ua.MessageType.SecureMessage) -> None:
        # As UaProcessor.send_response (asyncua 2.1.0), with our encoder.
        response.ResponseHeader.RequestHandle = requesthandle
        data = self._connection.message_to_binary(encode_response(response), message_type=msgtype,
                                                  request_id=seqhdr.RequestId)
        self._transport.write(data)

    def open_secure_channel(self, algohdr: Any, seqhdr: Any, body: Any) -> None:
        try:
            super().open_secure_channel(algohdr, seqhdr, body)
        except ua.UaError as error:
            raise PolicyRefused(str(error)) from None

    async def _process_message(self, typeid: ua.NodeId, requesthdr: Any, seqhdr: Any, body: Any) -> Any:
        if getattr(self._connection.security_policy, "discovery_only", False) and typeid not in _DISCOVERY:
            raise ServiceError(ua.StatusCodes.BadSecurityPolicyRejected)
        if typeid == _WRITE or typeid == _READ:
            return await self._read_or_write(typeid, requesthdr, seqhdr, body)
        if typeid in _REGISTRATION:  # we are no discovery server; asyncua would accept them without a session
            raise ServiceError(ua.StatusCodes.BadServiceUnsupported)
        if typeid == _CREATE_SESSION:
            await self._check_channel_certificate(body)
        if typeid == _ACTIVATE_SESSION and not await self._password_accepted(requesthdr, body):
            # Answered here: asyncua would log an error line with each refused login.
            response = ua.ServiceFault()
            response.ResponseHeader.ServiceResult = ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
            self.send_response(requesthdr.RequestHandle, seqhdr, response)
            return True
        if typeid == _BROWSE or typeid == _BROWSE_NEXT:
            return await self._browse(typeid, requesthdr, seqhdr, body)
        answered = await super()._process_message(typeid, requesthdr, seqhdr, body)
        if typeid == _ACTIVATE_SESSION and self.session is not None and isinstance(self.session.user, SessionUser):
            self.session.user.peer = peer_host(self.name)
        return answered

    async def close(self) -> None:
        # Called when the connection is lost, and by asyncua's session watchdog when the client
        # sent nothing for the session timeout. Publish requests that came by this connection can
        # no longer be answered: dropped, so no subscription takes one for a sign of life.
        self._publish_requests.clear()
        self._publish_results_subs.clear()
        await super().close()
        session = self.session
        service = self.iserver.subscription_service
        if session is not None and session.state != SessionState.Closed and isinstance(service, GuardedSubscriptionService):
            await service.put_to_sleep(session.session_id)  # kept for a comeback, but no work per change meanwhile
        transport = self._transport
        if transport is not None and not transport.is_closing():
            # The session timed out on an open connection: its client hung or its cable was pulled
            # (no TCP reset). Nothing would ever close the connection; a live client reconnects.
            transport.close()

    def _active_session(self, typeid: ua.NodeId, body: Buffer) -> Any:
        """The session, after the checks UaProcessor._process_message makes before a session service."""
        session = self.session
        if session is None:
            raise ua.uaerrors.BadUserAccessDenied
        permissions = self._connection.security_policy.permissions
        if permissions is not None and not permissions.check_validity(session.user, typeid, body):
            raise ua.uaerrors.BadUserAccessDenied
        self.session_last_activity = time.monotonic()
        session.touch()
        if not session.is_activated():
            raise ServiceError(ua.StatusCodes.BadSessionNotActivated)
        return session

    async def _read_or_write(self, typeid: ua.NodeId, requesthdr: Any, seqhdr: Any, body: Buffer) -> bool:
        """Read and Write as asyncua 2.1.0 serves them, found without its search (see the module docstring)."""
        session = self._active_session(typeid, body)
        if typeid == _WRITE:
            results = await session.write(struct_from_binary(ua.WriteParameters, body))
            self.send_response(requesthdr.RequestHandle, seqhdr, ua.WriteResponse(Results=results))
        else:
            results = await session.read(struct_from_binary(ua.ReadParameters, body))
            self.send_response(requesthdr.RequestHandle, seqhdr, ua.ReadResponse(Results=results))
        return True

    async def _browse(self, typeid: ua.NodeId, requesthdr: Any, seqhdr: Any, body: Buffer) -> bool:
        """Browse and BrowseNext with continuation points (asyncua ignores RequestedMaxReferencesPerNode)."""
        session = self._active_session(typeid, body)
        if self._continuation_session is not session:  # points belong to a session
            self._continuation_points, self._continuation_session = ContinuationPoints(), session
        points = self._continuation_points
        assert points is not None
        if typeid == _BROWSE:
            params = struct_from_binary(ua.BrowseParameters, body)
            results = await session.browse(params)
            points.page(results, params.RequestedMaxReferencesPerNode)
            self.send_response(requesthdr.RequestHandle, seqhdr, ua.BrowseResponse(Results=results))
        else:
            next_params = struct_from_binary(ua.BrowseNextParameters, body)
            results = points.next(next_params.ContinuationPoints, next_params.ReleaseContinuationPoints)
            self.send_response(requesthdr.RequestHandle, seqhdr, ua.BrowseNextResponse(Parameters=ua.BrowseNextResult(Results=results)))
        return True

    async def _check_channel_certificate(self, body: Buffer) -> None:
        """Raise a ServiceError unless the certificate of a secured channel passes the validator."""
        channel_certificate = self._connection.security_policy.peer_certificate
        validator = self.iserver.certificate_validator
        if not channel_certificate or validator is None:
            return  # a None channel: no certificate proves anything
        params = struct_from_binary(ua.CreateSessionParameters, body.copy())  # asyncua decodes its own
        if params.ClientCertificate and _leaf(params.ClientCertificate) != _leaf(channel_certificate):
            raise ServiceError(ua.StatusCodes.BadCertificateInvalid)
        try:
            certificate = x509.load_der_x509_certificate(_leaf(channel_certificate))
        except ValueError:
            raise ServiceError(ua.StatusCodes.BadCertificateInvalid) from None
        await validator(certificate, params.ClientDescription)

    async def _password_accepted(self, requesthdr: Any, body: Buffer) -> bool:
        """Decide a UserName login before asyncua's synchronous ActivateSession asks the user
        manager, which then finds the success remembered. False: refuse the request. Anything
        that is not a password login (or that asyncua refuses anyway) passes through."""
        check = getattr(self.iserver.user_manager, "check_password", None)
        session = self.session or self.iserver.lookup_external_session(requesthdr.AuthenticationToken)
        if check is None or session is None:
            return True
        try:
            params = struct_from_binary(ua.ActivateSessionParameters, body.copy())  # asyncua decodes its own
            token = params.UserIdentityToken
            if not isinstance(token, ua.UserNameIdentityToken) or not token.UserName:
                return True
            try:
                name, password = self.iserver.decrypt_user_token(session, token)
            except UnicodeDecodeError as error:
                # A password that is not UTF-8 (asyncua would answer with an error line per
                # login): decoded as the user name is, so the login check refuses and logs it.
                name, password = token.UserName, bytes(error.object).decode("utf-8", "surrogateescape")
        except Exception:  # noqa: BLE001
            return True  # asyncua fails the same way: BadIdentityTokenInvalid, or a decoding error
        return bool(await check(peer_host(self.name), name, password or ""))


def _leaf(der: bytes) -> bytes:
    """The first certificate of a DER blob that may hold a chain (certificates one after another)."""
    if len(der) < 2 or der[0] != 0x30:
        return der
    if der[1] < 0x80:
        return der[:2 + der[1]]
    width = der[1] & 0x7F
    return der[:2 + width + int.from_bytes(der[2:2 + width], "big")]

