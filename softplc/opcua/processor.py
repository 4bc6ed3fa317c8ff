"""How requests are served: asyncua's UaProcessor with the gaps of asyncua 2.1.0 (pinned) closed.

- A client may use a SecurityPolicy None channel for sessions even when None is not offered
  (the channel falls back to asyncua's initial None policy). Here a None channel that was not
  offered serves discovery only (GetEndpoints, FindServers: what every client needs before it
  opens a secured channel); any other request on it gets BadSecurityPolicyRejected.
- RegisterServer needs no session in asyncua: anyone could add entries to FindServers. We are
  not a discovery server, so it is refused (BadServiceUnsupported).
"""

from __future__ import annotations

from typing import Any

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.security_policies import SecurityPolicyNone
from asyncua.server.uaprocessor import UaProcessor


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
