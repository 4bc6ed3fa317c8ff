"""The OPC UA latency client's subscription on Ready, read in asyncua's publish loop itself.

asyncua 2.1.0 (pinned) hands every notification to a subscription handler in a task of its own,
and its publish loop sends the next Publish request before that task has run. For a client that
answers a notification with a Write, that put on the answer's path: a task switch, the encoding
of a Publish request, and on the server the handling of that Publish request ahead of the Write
(measured at a 1 ms scan: about a third of the time from the notification's arrival to the
Write on the wire). `ReadySubscription` reads each PublishResult where the publish loop decodes
it and tells its `Listener` at once; the listener answers right there, in the publish loop
(`Listener.published`), or holds the next Publish request back until its answer has been sent,
so the server sees the Write first. A client may send its Publish requests whenever it likes; the notifications of
the moment stay queued on the server until the next one arrives.

`publish_decoded` is asyncua's session.publish with the PublishResponse decoded by
`response_decoding` (the same objects, made without asyncua's generic decoder, which runs cold
between two notifications 100-500 ms apart).
"""

from __future__ import annotations

import logging
import time
from typing import Any, Protocol

from asyncua import ua
from asyncua.common.subscription import Subscription
from asyncua.ua.uaerrors import UaStructParsingError

from softplc.latency.response_decoding import decode_publish_response

log = logging.getLogger(__name__)


class Listener(Protocol):
    """What a ReadySubscription tells, in the order the server published it."""

    def value_changed(self, value: Any, received: float) -> None:
        """A pushed value of the one monitored node; `received`: monotonic s when its PublishResult arrived."""

    def status_changed(self, status: ua.StatusCode) -> None:
        """The server changed the subscription's status (e.g. it timed out)."""

    async def published(self) -> None:
        """Called after each PublishResult; the next Publish request is sent when this returns (an
        answer may be written meanwhile)."""


class ReadySubscription(Subscription):
    """An asyncua Subscription of one monitored node whose PublishResults go straight to a Listener."""

    def __init__(self, session: Any, params: ua.CreateSubscriptionParameters, listener: Listener) -> None:
        super().__init__(session, params, handler=None)
        self.listener = listener

    async def publish_callback(self, publish_result: ua.PublishResult) -> None:
        received = time.monotonic()
        self.last_publish_at = received  # asyncua's own bookkeeping, as its publish_callback keeps it
        message = publish_result.NotificationMessage
        if message.NotificationData:
            self.last_sequence_number = int(message.SequenceNumber)
            for notification in message.NotificationData:
                if isinstance(notification, ua.DataChangeNotification):
                    # One node is monitored: every item is that node's value.
                    for item in notification.MonitoredItems:
                        value = item.Value.Value.Value if item.Value is not None and item.Value.Value is not None else None
                        self.listener.value_changed(value, received)
                elif isinstance(notification, ua.StatusChangeNotification):
                    self.listener.status_changed(notification.Status)
        await self.listener.published()


async def publish_decoded(session: Any, acks: list[ua.SubscriptionAcknowledgement]) -> ua.PublishResponse:
    """As asyncua 2.1.0's UaSession.publish (its publish loop calls `session.publish`), decoding
    with `decode_publish_response`; install with `session.publish = functools.partial(publish_decoded, session)`."""
    request = ua.PublishRequest()
    request.Parameters.SubscriptionAcknowledgements = acks if acks else []
    data = await session._send_request(request, timeout=0)
    try:
        return decode_publish_response(data)
    except Exception as error:
        log.exception("Error parsing notification from server")
        raise UaStructParsingError from error
