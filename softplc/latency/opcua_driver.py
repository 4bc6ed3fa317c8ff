"""The handshake over OPC UA (asyncua client): by subscription or by polling.

Node ids are given per role; `{ns}` in a node id stands for the namespace index of
`namespace` (a URI) or, when none is given, of softplc's tag namespace (urn:softplc:tags) if
the server has it, else of the server's last namespace. Writes carry the node's own variant type (servers check it strictly).

By subscription, Ready's notifications are read in asyncua's publish loop (ready_subscription.py):
the client notes when it saw Ready as the PublishResponse is decoded, and its answer goes on the
wire before the next Publish request.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from typing import Any

from asyncua import Client, Node, ua
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

from softplc.latency.certificate import MODES, Security, application_uri
from softplc.latency.driver import REQUIRED_ROLES, TAG_NAMES, DriverError, PollingDriver, ReadyTracker, Snapshot
from softplc.latency.ready_subscription import ReadySubscription, publish_decoded
from softplc.latency.response_decoding import decode_write_response

log = logging.getLogger(__name__)

SOFTPLC_NAMESPACE = "urn:softplc:tags"
DEFAULT_NODE_IDS: dict[str, str] = {role: f"ns={{ns}};s={name}" for role, name in TAG_NAMES.items()}
# Longest the next Publish request waits for the answer to a Ready just seen (it comes at once;
# this bounds a client that stopped answering).
ANSWER_GATE_SECONDS = 1.0


class OpcuaDriver(PollingDriver):
    """An asyncua client session on the handshake tags."""

    def __init__(
        self,
        endpoint: str,
        node_ids: dict[str, str],
        *,
        subscription: bool = True,
        publishing_interval: float = 0.0,
        poll_interval: float = 0.001,
        namespace: str | None = None,
        security: str | None = None,
        user: str | None = None,
        password: str | None = None,
        timeout: float = 4.0,
    ) -> None:
        missing = [role for role in REQUIRED_ROLES if not node_ids.get(role)]
        if missing:
            raise DriverError(f"no node id for {', '.join(missing)}")
        self.endpoint = endpoint
        self.node_ids = {role: node_id for role, node_id in node_ids.items() if node_id}
        self.subscription = subscription
        self.publishing_interval = publishing_interval
        self.poll_interval = poll_interval
        self.namespace = namespace
        self.security = security
        self.client = Client(endpoint, timeout=timeout)
        if user:
            self.client.set_user(user)
            self.client.set_password(password or "")
        self.nodes: dict[str, Node] = {}
        self.types: dict[str, ua.VariantType] = {}
        self._roles: list[str] = []
        self._latest: dict[str, Any] = {}
        self._push_waiter: asyncio.Future[None] | None = None  # wait_ready or settle waiting for a push
        self._answer_gate: asyncio.Future[None] | None = None  # the publish loop waiting for our answer
        self._ready_seen_at = 0.0
        # Subscription mode answers each pushed rise of Ready (Ready is all it monitors).
        self._rises = 0
        self._answered_rises = 0
        self._write_request: ua.WriteRequest | None = None  # the answer, built once (see _write)
        self._prepared: int | None = None  # the TaskID to answer the next new Ready with, where it arrives
        self._ahead: asyncio.Future[tuple[int, float, float]] | None = None  # that answer: (TaskID, sent, done)
        self._awaiting_ready = False  # wait_ready is waiting: a rise will be answered at once
        mode = f"subscription, publishing interval {publishing_interval:g} ms" if subscription else f"polling every {poll_interval * 1e3:g} ms"
        secured = security.split(",")[0] if security else "None"
        self.description = f"OPC UA {endpoint} ({mode}; security {secured})"

    @property
    def serves(self) -> set[str]:
        return set(self.nodes)

    async def connect(self) -> None:
        if self.security:
            await self._secure(Security.parse(self.security))
        try:
            await self.client.connect()
        except Exception as error:
            raise DriverError(f"cannot connect to {self.endpoint}: {error!r}") from None
        namespace_index = await self._namespace_index()
        for role, node_id in self.node_ids.items():
            text = node_id.replace("{ns}", str(namespace_index))
            try:
                node = self.client.get_node(text)
                self.types[role] = await node.read_data_type_as_variant_type()
            except Exception as error:
                raise DriverError(f"{role}: node {text} is not readable: {error!r}") from None
            self.nodes[role] = node
        self._roles = list(self.nodes)
        if self.subscription:
            await self._subscribe()

    async def _secure(self, security: Security) -> None:
        if not security.secured:
            return
        if security.certificate is None or security.key is None:
            raise DriverError("--security Sign/SignAndEncrypt needs the client certificate and key: MODE,CERT,KEY")
        self.client.application_uri = application_uri(security.certificate)
        try:
            await self.client.set_security(SecurityPolicyBasic256Sha256, str(security.certificate), str(security.key), mode=MODES[security.mode])
        except Exception as error:
            raise DriverError(f"cannot set up {security.mode} security: {error!r}") from None

    async def _namespace_index(self) -> int:
        names = await self.client.get_namespace_array()
        if self.namespace is None:
            # softplc's tag namespace if the server has it, else the server's last one.
            return names.index(SOFTPLC_NAMESPACE) if SOFTPLC_NAMESPACE in names else len(names) - 1
        if self.namespace not in names:
            raise DriverError(f"the server has no namespace {self.namespace!r}; it has: {', '.join(names)}")
        return names.index(self.namespace)

    async def _subscribe(self) -> None:
        params = ua.CreateSubscriptionParameters()
        params.RequestedPublishingInterval = self.publishing_interval
        params.RequestedLifetimeCount = 10000
        # A keep-alive at least every few seconds, even with a 0 ms publishing interval.
        params.RequestedMaxKeepAliveCount = 10000 if self.publishing_interval <= 0 else max(3, int(3000 / self.publishing_interval))
        params.MaxNotificationsPerPublish = 0
        params.PublishingEnabled = True
        params.Priority = 0
        # As Client.create_subscription, with the subscription class that reads PublishResults inline,
        # and the session's publish decoding them the short way.
        session = self.client.uaclient.session
        session.publish = functools.partial(publish_decoded, session)
        self._sub = ReadySubscription(session, params, self)
        await self._sub.init()
        # Only Ready is monitored. Every other monitored tag that changes with it would be queued
        # and published when our next Publish request arrives, which the server handles just
        # before our Write: measured, that put ~0.7 ms of publishing in front of every answer.
        # The other figures are read once per handshake after the answer (see settle).
        ready = self.nodes["ready"]
        try:
            await self._sub.subscribe_data_change(ready, queuesize=1, sampling_interval=0.0)
        except Exception as error:
            raise DriverError(f"cannot subscribe to Ready ({ready.nodeid.to_string()}): {error!r}") from None

    def value_changed(self, value: Any, received: float) -> None:
        """Ready as pushed, in the order the server sent it (ReadySubscription calls this)."""
        self._latest["ready"] = value
        if value:
            self._ready_seen_at = received
            self._rises += 1
        waiter = self._push_waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def status_changed(self, status: ua.StatusCode) -> None:
        log.warning("subscription status changed: %s", status)

    def prepare(self, task_id: int) -> None:
        self._prepared = task_id

    async def published(self) -> None:
        """Answer a Ready just seen here, or hold the next Publish request back until it is answered."""
        if not (self._awaiting_ready and self._rises > self._answered_rises):
            return
        task_id, self._prepared = self._prepared, None
        if task_id is not None:
            # The answer goes out where Ready arrived, in asyncua's publish loop: no task switch
            # between seeing Ready and the Write; the next Publish request follows the response.
            ahead = self._ahead = asyncio.get_running_loop().create_future()
            sent = time.monotonic()
            try:
                await self._write(task_id)
            except DriverError as error:
                ahead.set_exception(error)
            else:
                ahead.set_result((task_id, sent, time.monotonic()))
            return
        gate = self._answer_gate = asyncio.get_running_loop().create_future()
        try:
            await asyncio.wait_for(gate, ANSWER_GATE_SECONDS)
        except TimeoutError:
            pass
        finally:
            self._answer_gate = None

    def _open_gate(self) -> None:
        gate = self._answer_gate
        if gate is not None and not gate.done():
            # The publish loop resumes once this task waits for the Write's response: after the
            # Write has gone out (asyncua sends it before its first wait).
            gate.set_result(None)

    async def close(self) -> None:
        self._open_gate()
        ahead = self._ahead
        if ahead is not None and ahead.done() and not ahead.cancelled():
            ahead.exception()  # an answer ahead that failed as the run ended: reported by the run, if at all
        try:
            await self.client.disconnect()
        except Exception as error:  # the server may be gone already
            log.debug("disconnect: %r", error)

    async def read(self) -> Snapshot:
        try:
            values = await self.client.read_values([self.nodes[role] for role in self._roles])
        except Exception as error:
            raise DriverError(f"read failed: {error!r}") from None
        return _snapshot(dict(zip(self._roles, values)), time.monotonic())

    async def answer(self, task_id: int) -> tuple[float, float] | None:
        self._prepared = None
        ahead, self._ahead = self._ahead, None
        if ahead is not None:
            answered, sent, done = await ahead  # DriverError if it failed
            if answered == task_id:
                return sent, done
        self._open_gate()
        await self._write(task_id)
        return None

    async def _write(self, task_id: int) -> None:
        """Write TaskID and clear Ready in one request; DriverError if it failed or was refused."""
        # One WriteRequest object, built at the first answer, with the new TaskID put in each time,
        # sent by the connection's protocol as asyncua's session.write sends it (the request's
        # header is set there): building the nodes' WriteValues and going through write_values'
        # layers cost ~0.13 ms of CPU per answer at a 1 ms scan (code run once every 100-500 ms
        # runs cold), more than encoding the request (bench/latency_trace.py).
        request = self._write_request
        if request is None:
            items = [ua.WriteValue(NodeId=self.nodes["task_id"].nodeid, AttributeId=ua.AttributeIds.Value,
                                   Value=ua.DataValue(ua.Variant(task_id, self.types["task_id"]))),
                     ua.WriteValue(NodeId=self.nodes["ready"].nodeid, AttributeId=ua.AttributeIds.Value,
                                   Value=ua.DataValue(ua.Variant(False, self.types["ready"])))]
            request = self._write_request = ua.WriteRequest(Parameters=ua.WriteParameters(NodesToWrite=items))
        request.Parameters.NodesToWrite[0].Value.Value.Value = task_id
        protocol = self.client.uaclient.protocol
        if protocol is None:
            raise DriverError("write failed: the connection to the server is closed")
        try:
            data = await protocol.send_request(request)
            response = decode_write_response(data)
            response.ResponseHeader.ServiceResult.check()
            results = response.Results
        except Exception as error:
            raise DriverError(f"write failed: {error!r}") from None
        bad = [f"{role}: {result.name}" for role, result in zip(("TaskID", "Ready"), results) if not result.is_good()]
        if bad:
            hint = ""
            if any(result.name == "BadUserAccessDenied" for result in results):
                hint = (" — this session may not write. Log in as a user who may: --user NAME with the password in "
                        "$SOFTPLC_LATENCY_PASSWORD (on a softplc, anonymous sessions only read; add an operator with "
                        "`softplc users add NAME --role operator --config CONFIG`, see docs/latency.md)")
            raise DriverError("write refused: " + ", ".join(bad) + hint)

    async def wait_ready(self, tracker: ReadyTracker, timeout: float) -> Snapshot:
        if not self.subscription:
            return await super().wait_ready(tracker, timeout)
        deadline = time.monotonic() + timeout
        self._awaiting_ready = True
        try:
            while True:
                snapshot = self._cached()
                if snapshot is not None and snapshot.ready and self._rises > self._answered_rises:
                    self._answered_rises = self._rises
                    return snapshot.at(self._ready_seen_at or time.monotonic())
                await self._wait_push(deadline, f"no new Ready pushed within {timeout:g} s")
        except TimeoutError as error:
            raise TimeoutError(f"{error} ({self._last_push()})") from None
        finally:
            self._awaiting_ready = False

    def _last_push(self) -> str:
        """What the subscription last brought, for a timeout's message."""
        last = getattr(self._sub, "last_publish_at", None)
        ago = f"{time.monotonic() - last:.1f} s ago" if last else "never"
        return f"last PublishResponse {ago}; Ready {'high' if self._latest.get('ready') else 'low'} as last pushed"

    async def settle(self, ready: Snapshot, handshakes: int | None, timeout: float) -> Snapshot:
        if not self.subscription:
            return await super().settle(ready, handshakes, timeout)
        # Ready goes low in the scan that applies our answer; then a Read gets the figures. The
        # server mirrors a scan's changes into its address space one by one, so Handshakes may
        # show its new value a moment after Ready: read until it does (or the wait is over).
        deadline = time.monotonic() + timeout
        while self._latest.get("ready"):
            try:
                await self._wait_push(deadline, "")
            except TimeoutError:
                break
        while True:
            snapshot = await self.read()
            if handshakes is None or snapshot.handshakes != handshakes or snapshot.received >= deadline:
                return snapshot
            await asyncio.sleep(self.poll_interval)

    def rearm(self) -> None:
        self._answered_rises = self._rises - 1

    def _cached(self) -> Snapshot | None:
        if "ready" not in self._latest:
            return None
        return _snapshot(self._latest, time.monotonic())

    async def _wait_push(self, deadline: float, message: str) -> None:
        """Return at the next pushed value; raise TimeoutError(message) at `deadline`."""
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError(message)
        # A bare future woken by value_changed: the waiting task resumes in the loop's next turn
        # (an Event waited on through wait_for takes a task and two more turns).
        loop = asyncio.get_running_loop()
        waiter = self._push_waiter = loop.create_future()
        timer = loop.call_later(remaining, _expire, waiter, message)
        try:
            await waiter
        finally:
            timer.cancel()
            self._push_waiter = None


def _expire(waiter: asyncio.Future[None], message: str) -> None:
    if not waiter.done():
        waiter.set_exception(TimeoutError(message))


def _number(value: Any, kind: type) -> Any:
    return None if value is None else kind(value)


def _snapshot(values: dict[str, Any], received: float) -> Snapshot:
    def number(role: str, kind: type) -> Any:
        return _number(values.get(role), kind)

    return Snapshot(
        ready=bool(values.get("ready")),
        task_id=number("task_id", int),
        delay=number("delay", float),
        delay_scans=number("delay_scans", int),
        handshakes=number("handshakes", int),
        ready_stamp=number("ready_stamp", float),
        received=received,
    )
