"""A link to an OPC UA server: bound nodes by one subscription (one monitored-item batch), writes in one request.

At connect the link reads every bound node's DataType and access level in one request each: a
node the remote does not have, of a type the tag cannot hold, or that our user may not write
(for `out` and `both` tags) is a binding problem — an error at start when the remote answers
then, the tag BAD with the reason later. Then it subscribes to the nodes read from the remote
(`in` and `both`) in one CreateMonitoredItems request and takes each notification's value:
a status that is not good, or a value the tag cannot hold, makes the tag BAD (UNCERTAIN for an
uncertain status) with the reason, keeping its last good value.

Liveness: every publish response (data or keep-alive) counts as data; when none came for a
period the link reads the server's clock (a heartbeat), so a silent remote is noticed at the
period's pace whatever the subscription's keep-alive. asyncua's own watchdog reports a lost
connection (`connection_lost_callback`); the link then reconnects with its own backoff.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Sequence
from typing import Any

from asyncua import Client, ua
from asyncua.common.subscription import DataChangeEvent, Subscription

from softplc.adapters.links.link import Link, LinkError
from softplc.adapters.links.quality import BoundTag
from softplc.adapters.links.settings import Binding, LinkSettings
from softplc.core.plant import Plant
from softplc.core.tags import Quality
from softplc.protocols.opcua_client import ClientCertificate, client_certificate, ensure_client_certificate, make_client
from softplc.protocols.opcua_names import DEFAULT_NAMESPACE
from softplc.protocols.opcua_remote import binding_problem, remote_variant, status_text, tag_value, variant_type_of
from softplc.util.tasks import within

log = logging.getLogger(__name__)

SECURITY = {"Sign": "Basic256Sha256_Sign", "SignAndEncrypt": "Basic256Sha256_SignAndEncrypt"}
SERVER_TIME = ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime)
_WRITABLE = ua.AccessLevel.CurrentWrite.mask


class OpcuaLink(Link):
    """Subscribes to an OPC UA server (see the module docstring)."""

    def __init__(self, settings: LinkSettings, plant: Plant) -> None:
        super().__init__(settings, plant)
        self.client: Client | None = None
        self.subscription: Subscription | None = None
        self.node_ids: dict[str, ua.NodeId] = {}  # tag → its node on the remote
        self.variant_types: dict[str, ua.VariantType] = {}
        self.problems: dict[str, str] = {}  # tag → why the remote cannot serve its binding
        self._lost: asyncio.Future[str] | None = None
        self._incoming: list[DataChangeEvent] = []
        self.notifications = 0
        self.session_at: float | None = None  # clock time the remote answered (its session open): bench/links_opcua_subscribe.py
        self.subscribed_at: float | None = None  # clock time the monitored items were created

    # -- connection ---------------------------------------------------------------------

    async def connect(self) -> None:
        settings = self.settings
        self.problems = {}
        loop = asyncio.get_running_loop()
        self._lost = loop.create_future()
        try:
            self.client = await make_client(
                settings.endpoint, user=settings.user, password=settings.password(), certificate=self._certificate(),
                security=SECURITY.get(settings.security, "None"), timeout=settings.timeout,
                watchdog_interval=max(settings.period * 5, settings.timeout),
            )
        except (OSError, ValueError) as error:
            raise LinkError(f"cannot prepare the connection: {error}") from None
        self.client.connection_lost_callback = self._connection_lost
        await self._call(self.client.connect(), "connecting")
        self.session_at = self.clock.now()
        await self._resolve()
        # Both at once: the subscription need not wait for the types (a value carries its own);
        # a node the check finds wrong is never taken from (`_take`).
        await asyncio.gather(self._check_nodes(), self._subscribe())

    async def close(self) -> None:
        client, self.client, self.subscription = self.client, None, None
        if client is not None:
            try:
                await within(self.settings.timeout, client.disconnect())
            except (OSError, TimeoutError, ua.UaError, ConnectionError):
                client.disconnect_socket()

    async def _connection_lost(self, error: Exception) -> None:
        if self._lost is not None and not self._lost.done():
            self._lost.set_result(f"connection lost: {_short(error)}")

    def _certificate(self) -> ClientCertificate | None:
        settings = self.settings
        if settings.security == "None":
            return None
        if settings.certificate is not None and settings.private_key is not None:
            return client_certificate(settings.certificate, settings.private_key)
        # One certificate for every link of this plant: the remote's administrator trusts it once.
        return ensure_client_certificate(self.plant.state_dir / "pki" / "links", "softplc-links")

    async def _call(self, request: Any, what: str) -> Any:
        """One request; LinkError says what failed, in the remote's words where it gave any."""
        self.requests += 1
        try:
            return await within(self.settings.timeout * 2, request)
        except ua.UaStatusCodeError as error:
            hint = ""
            if "BadCertificate" in type(error).__name__ or "BadSecurityChecksFailed" in type(error).__name__:
                certificate = self._certificate()
                if certificate is not None:
                    hint = f" (the remote must trust our certificate {certificate.certificate}, fingerprint {certificate.fingerprint})"
            raise LinkError(f"{what}: the remote answered {type(error).__name__}{hint}") from None
        except (OSError, TimeoutError, ConnectionError, ua.UaError, asyncio.IncompleteReadError) as error:
            raise LinkError(f"{what}: {_short(error)}") from None

    async def _resolve(self) -> None:
        """Node ids with {ns} take the index of the link's namespace (or softplc's tags, else the remote's last)."""
        assert self.client is not None
        index = 0
        if any("{ns}" in bound.binding.source for bound in self.bound.values()):
            names = await self._call(self.client.get_namespace_array(), "reading the namespaces")
            wanted = self.settings.namespace or (DEFAULT_NAMESPACE if DEFAULT_NAMESPACE in names else names[-1])
            if wanted not in names:
                raise LinkError(f"the remote has no namespace {wanted!r} (it has {', '.join(names)})")
            index = names.index(wanted)
        self.node_ids = {name: ua.NodeId.from_string(bound.binding.source.replace("{ns}", str(index)))
                         for name, bound in self.bound.items()}

    async def _check_nodes(self) -> None:
        """Every bound node exists, has a type the tag can hold and, for writes, may be written by us."""
        assert self.client is not None
        names = list(self.bound)
        ids = [self.node_ids[name] for name in names]
        types = await self._call(self.client.uaclient.read_attributes(ids, ua.AttributeIds.DataType), "reading the bound nodes' types")
        writers = [name for name in names if self.bound[name].binding.direction.writes]
        access = await self._call(self.client.uaclient.read_attributes([self.node_ids[n] for n in writers], ua.AttributeIds.UserAccessLevel),
                                  "reading the bound nodes' access levels") if writers else []
        for name, answer in zip(names, types):
            binding = self.bound[name].binding
            if not answer.StatusCode.is_good():
                self.problems[name] = f"node {binding.source} of the remote: {status_text(answer.StatusCode)}"
                continue
            data_type = answer.Value.Value
            variant_type = variant_type_of(data_type) if isinstance(data_type, ua.NodeId) else None
            problem = binding_problem(binding.tag.type, data_type) if isinstance(data_type, ua.NodeId) else "no DataType"
            if problem is not None:
                self.problems[name] = f"node {binding.source}: {problem}"
                continue
            assert variant_type is not None
            self.variant_types[name] = variant_type
        for name, answer in zip(writers, access):
            if name not in self.problems and answer.StatusCode.is_good() and not int(answer.Value.Value or 0) & _WRITABLE:
                who = f"user {self.settings.user}" if self.settings.user else "an anonymous session"
                self.problems[name] = f"node {self.bound[name].binding.source} is not writable for {who} (direction {self.bound[name].binding.direction.value})"
        for name, reason in self.problems.items():
            self.bound[name].bad(reason)

    def binding_problems(self) -> list[tuple[Binding, str]]:
        return [(self.bound[name].binding, reason) for name, reason in self.problems.items()]

    async def _subscribe(self) -> None:
        assert self.client is not None
        readers = self.readers
        publishing = self.settings.period if self.settings.publishing_interval is None else self.settings.publishing_interval
        params = ua.CreateSubscriptionParameters(
            RequestedPublishingInterval=publishing * 1000.0, RequestedLifetimeCount=10000,
            # A keep-alive at least every period when nothing changes (with publishing at once: none; the heartbeat covers it).
            RequestedMaxKeepAliveCount=max(1, math.ceil(self.settings.period / publishing)) if publishing > 0 else 10000,
            MaxNotificationsPerPublish=0, PublishingEnabled=True, Priority=0,
        )
        # Iterator mode: notifications queue up and are taken in one batch per loop turn.
        self.subscription = await self._call(self.client.create_subscription(params, None, queue_maxsize=0), "creating the subscription")
        if not readers:
            return
        nodes = [self.client.get_node(self.node_ids[bound.name]) for bound in readers]
        handles = await self._call(self.subscription.subscribe_data_change(nodes, queuesize=1, sampling_interval=0), "subscribing")
        self.subscribed_at = self.clock.now()
        for bound, handle in zip(readers, handles):
            if isinstance(handle, ua.StatusCode):
                # The type check's reason (a missing node) says more, whichever answer comes first.
                reason = self.problems.setdefault(bound.name, f"node {bound.binding.source}: the remote refused to monitor it: {status_text(handle)}")
                bound.bad(reason)

    # -- reading ------------------------------------------------------------------------

    async def exchange(self) -> None:
        assert self._lost is not None and self.subscription is not None
        consumer = asyncio.ensure_future(self._consume(self.subscription))
        heartbeat = asyncio.ensure_future(self._heartbeat())
        try:
            done, _ = await asyncio.wait({consumer, heartbeat, self._lost}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            consumer.cancel()
            heartbeat.cancel()
        if self._lost.done():
            raise LinkError(self._lost.result())
        for task in done:
            error = task.exception()
            if error is not None:
                raise error if isinstance(error, LinkError) else LinkError(_short(error))
        raise LinkError("the subscription ended")

    async def _consume(self, subscription: Subscription) -> None:
        loop = asyncio.get_running_loop()
        async for event in subscription:
            if not isinstance(event, DataChangeEvent):
                continue
            if not self._incoming:
                # The iterator does not yield while events are queued: this runs once the batch is in.
                loop.call_soon(self._take)
            self._incoming.append(event)

    def _take(self) -> None:
        events, self._incoming = self._incoming, []
        by_node = {node_id: name for name, node_id in self.node_ids.items()}
        changed: list[BoundTag] = []
        for event in events:
            name = by_node.get(event.node.nodeid)
            if name is None or name in self.problems:
                continue
            bound = self.bound[name]
            data_value = event.data.monitored_item.Value
            self._note(bound, data_value)
            changed.append(bound)
        self.notifications += len(events)
        self.answered()
        self.received(changed)

    def _note(self, bound: BoundTag, data_value: ua.DataValue) -> None:
        status = data_value.StatusCode or ua.StatusCode(ua.StatusCodes.Good)
        if status.is_bad():
            bound.bad(f"the remote says {status_text(status)}")
            return
        try:
            value = tag_value(bound.binding.tag.type, data_value.Value)
        except ValueError as error:
            bound.bad(str(error))
            return
        bound.good(value)
        if status.is_uncertain():
            bound.bad(f"the remote says {status_text(status)}", Quality.UNCERTAIN)

    async def _heartbeat(self) -> None:
        """Every half period: a publish response since the last look is data; a period without any, a read of the server's clock."""
        subscription = self.subscription  # this connection's: close() forgets it
        assert self.client is not None and subscription is not None
        node = self.client.get_node(SERVER_TIME)
        seen = subscription.last_publish_at
        period = self.settings.period
        while True:
            await self.clock.sleep(period / 2)
            if subscription.last_publish_at != seen:
                seen = subscription.last_publish_at
                self.answered()
                continue
            if self.last_data is not None and self.clock.now() - self.last_data < period:
                continue
            started = self.clock.now()
            await self._call(node.read_value(), "heartbeat (reading the server's time)")
            self.answered(self.clock.now() - started)

    # -- writing ------------------------------------------------------------------------

    async def write(self, items: Sequence[tuple[BoundTag, Any]]) -> list[str | None]:
        answers: list[str | None] = [None] * len(items)
        sent: list[int] = []
        ids: list[ua.NodeId] = []
        values: list[ua.DataValue] = []
        for index, (bound, value) in enumerate(items):
            name = bound.name
            if name in self.problems or name not in self.variant_types:
                answers[index] = self.problems.get(name, "the remote's node type is not known yet")
                continue
            try:
                variant = remote_variant(value, self.variant_types[name])
            except ValueError as error:
                answers[index] = str(error)
                continue
            sent.append(index)
            ids.append(self.node_ids[name])
            values.append(ua.DataValue(variant))
        if not sent:
            return answers
        if self.client is None:
            raise LinkError("not connected")
        started = self.clock.now()
        results = await self._call(self.client.uaclient.write_attributes(ids, values, ua.AttributeIds.Value), "writing")
        self.round_trip = self.clock.now() - started
        for index, status in zip(sent, results):
            if not status.is_good():
                answers[index] = status_text(status)
        return answers

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "notifications": self.notifications, "binding_problems": len(self.problems)}


def _short(error: BaseException) -> str:
    text = str(error).strip()
    return f"{type(error).__name__}: {text}" if text else type(error).__name__
