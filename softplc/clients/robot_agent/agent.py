"""The remote robot agent: a robot's own computer running its driver as an OPC UA client.

    softplc robot-agent --endpoint opc.tcp://plc:4840/softplc/ --robot r01 --user r01 --password-file r01.pw

The agent loads its robot's configuration (robots.yaml) and the map, connects, registers itself
by writing `rNN_agent` (id, name, hardware, host: nobody types its address anywhere), waits for
the runtime's answer in that tag, subscribes to its goal tags and to every robot's traffic tags,
and every cycle writes its pose and state as one `rNN_report`, which the runtime's fleet adapter
publishes to the robot's read-only tags. When the runtime goes away the robot stops where it
is, and the agent reconnects with exponential backoff; its driver (pose, path) survives the
reconnection.

A redundant pair of runtimes (docs/redundancy.md): `--endpoint URL1,URL2`. The agent connects
to the member whose ServiceLevel says it is active, registers there (a standby refuses the
registration) and follows the pair's epoch (`_sys.redundancy.epoch`): it obeys goals only from a
member that is ACTIVE with the highest epoch it has seen, and leaves a member that stops being
active to look for the new one. A fenced or older active's goals are ignored: the robot stops.

Some failures are not worth retrying and end `run()` with an `AgentError`: the runtime refused
the registration (it drives that robot itself, or has no such robot), or refused the login
`max_login_failures` times in a row (each refusal is logged as an error).
"""

from __future__ import annotations

import asyncio
import logging
import os
import socket
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import Client, ua

from softplc import __version__
from softplc.clients.login import REFUSALS
from softplc.core.clock import Clock, RealClock
from softplc.protocols.opcua_names import DEFAULT_NAMESPACE
from softplc.robotics.controller import SpeedLimits
from softplc.robotics.driver import Command, DriverSettings, Report, RobotDriver
from softplc.robotics.floor import Floor
from softplc.robotics.loop import ControlLoop
from softplc.robotics.peers import PEER_TAGS, PeerView
from softplc.robotics.protocol import Answer, Registration, encode_report
from softplc.robotics.robots import RobotFile, unknown_id_message
from softplc.util.tasks import within

log = logging.getLogger(__name__)

ANSWER_TIMEOUT = 10.0  # s the runtime has to answer a registration (it answers within a scan cycle)
LOGIN_REFUSALS = frozenset(getattr(ua.StatusCodes, name) for name in REFUSALS)  # softplc/clients/login.py


class AgentError(Exception):
    """The agent cannot go on (not worth retrying): the message says why and what to do."""


class Unanswered(Exception):
    """The runtime did not answer the registration in time (retried like a lost connection)."""


def login_refusal(error: BaseException) -> str:
    """The status name when `error` is the server refusing this client's login; '' otherwise."""
    if isinstance(error, ua.UaStatusCodeError) and error.code in LOGIN_REFUSALS:
        return ua.StatusCode(error.code).name
    return ""


@dataclass
class Credentials:
    """How the agent logs in: a user and password, and/or a client certificate."""

    user: str | None = None
    password: str | None = None
    certificate: Path | None = None
    private_key: Path | None = None
    security: str = "None"  # None | Basic256Sha256_Sign | Basic256Sha256_SignAndEncrypt


EPOCH, ROLE = "_sys.redundancy.epoch", "_sys.redundancy.role"


class Epochs:
    """The highest epoch of a redundant pair's active this agent has seen (0 alone), across sessions."""

    def __init__(self) -> None:
        self.highest = 0

    def obeys(self, role: Any, epoch: Any) -> bool:
        """Whether goals from a member with this role and epoch are obeyed (and the highest epoch noted)."""
        if role is None and epoch is None:
            return True  # a runtime alone
        if role != "ACTIVE" or not isinstance(epoch, int) or epoch < self.highest:
            return False
        self.highest = epoch
        return True


class SubscriptionIO:
    """The driver's inputs from OPC UA subscriptions, its output as one report write per cycle."""

    def __init__(self, client: Client, namespace: int, robot_id: str, ids: list[str], first_event: int, session: str = "",
                 epochs: Epochs | None = None, paired: bool = False) -> None:
        self.client = client
        self.epochs = epochs or Epochs()
        self.paired = paired  # the runtime is a member of a redundant pair: goals need its role and epoch
        self.id = robot_id
        self.ids = ids
        self.values: dict[str, Any] = {}
        self.session = session  # of our registration: the runtime's answer names it
        self.answer: Answer | None = None
        self.answered = asyncio.Event()
        self._report = client.get_node(ua.NodeId(f"{robot_id}_report", namespace))
        self._seq = 0
        self._first_event = first_event  # status events before this session are not re-sent
        self._status: tuple[int, bool] | None = None

    def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
        name = node.nodeid.Identifier
        self.values[name] = value
        if name == f"{self.id}_agent" and isinstance(value, str):
            answer = Answer.decode(value)
            if answer is not None and answer.session == self.session:
                self.answer = answer
                self.answered.set()

    def status_change_notification(self, status: Any) -> None:
        pass  # the session's end is noticed by the next write or the connection watchdog

    def obeyed(self) -> bool:
        """Whether this member's goals are obeyed now (alone: always; in a pair: the newest active only)."""
        if not self.paired:
            return True
        return self.epochs.obeys(self.values.get(ROLE), self.values.get(EPOCH))

    def command(self) -> Command | None:
        values = self.values
        if not self.obeyed():
            return None  # a standby's, a fenced or an older active's goals: the robot does not move for them
        try:
            return Command(float(values[f"{self.id}_xgoal"]), float(values[f"{self.id}_ygoal"]), bool(values[f"{self.id}_status"]))
        except (KeyError, TypeError, ValueError):
            return None  # not all goal tags have arrived yet

    def peers(self) -> PeerView:
        get = self.values.get
        return PeerView(self.ids, [[get(f"{robot_id}_{tag}") for tag in PEER_TAGS] for robot_id in self.ids])

    async def publish(self, report: Report) -> None:
        self._seq += 1
        if report.status is not None and report.status_seq >= self._first_event:
            self._status = (report.status_seq, report.status)
        seq, status = self._status if self._status is not None else (0, None)
        text = encode_report(self._seq, report, seq, status)
        await self._report.write_value(ua.DataValue(ua.Variant(text, ua.VariantType.String)))


class RobotAgent:
    """Keeps one robot connected to a runtime: connect, register, drive, reconnect."""

    def __init__(
        self,
        endpoint: str,
        robot_id: str,
        robots: RobotFile,
        floor: Floor,
        *,
        credentials: Credentials | None = None,
        namespace: str = DEFAULT_NAMESPACE,
        cycle: float = 0.1,
        limits: SpeedLimits | None = None,
        clock: Clock | None = None,
        max_backoff: float = 5.0,
        max_login_failures: int = 3,
    ) -> None:
        try:
            self.spec = robots[robot_id]
        except KeyError:
            raise KeyError(unknown_id_message("robot", robot_id, robots.ids)) from None
        self.endpoints = [part.strip() for part in endpoint.split(",") if part.strip()] or [endpoint]
        self.endpoint = self.endpoints[0]
        self.epochs = Epochs()
        self.robots = robots
        self.credentials = credentials or Credentials()
        self.namespace = namespace
        self.cycle = cycle
        self.clock = clock or RealClock()
        self.max_backoff = max_backoff
        self.max_login_failures = max_login_failures
        speed = limits or SpeedLimits(self.spec.max_linear_speed, self.spec.max_angular_speed)
        self.driver = RobotDriver(self.spec, floor, speed, DriverSettings(), cycle=cycle)
        self.connections = 0
        self.connected = asyncio.Event()

    async def run(self) -> None:
        """Connect and drive until cancelled, reconnecting with exponential backoff; AgentError when that is futile."""
        backoff = 0.5
        login_failures = 0
        robot_id = self.spec.id
        while True:
            try:
                await self._session()
                backoff = 0.5
            except (asyncio.CancelledError, AgentError):
                raise
            except Exception as error:  # any network or server failure: retry later
                refusal = login_refusal(error)
                if refusal:
                    login_failures += 1
                    who = f"user {self.credentials.user!r}" if self.credentials.user else "this client"
                    log.error("robot %s: %s refused the login of %s (%s): %s (try %d of %d)", robot_id, self.endpoint, who,
                              refusal, _login_hint(refusal, self.credentials), login_failures, self.max_login_failures)
                    if login_failures >= self.max_login_failures:
                        raise AgentError(f"{self.endpoint} refused the login of {who} {login_failures} times ({refusal}): "
                                         f"{_login_hint(refusal, self.credentials)}") from None
                elif isinstance(error, Unanswered):
                    log.warning("robot %s: %s at %s; trying again", robot_id, error, self.endpoint)
                elif self.connected.is_set():
                    log.warning("robot %s: lost the runtime at %s (%s); reconnecting", robot_id, self.endpoint, _describe(error))
                    backoff = 0.5
                else:
                    log.info("robot %s: cannot connect to %s (%s); retrying in %.1f s", robot_id, self.endpoint, _describe(error), backoff)
            if self.connected.is_set():
                login_failures = 0  # it was in: a refusal later is news, not a repeat
            self.connected.clear()
            await asyncio.sleep(backoff)  # network plumbing: real time, whatever the robot's clock
            backoff = min(self.max_backoff, backoff * 2)

    async def _session(self) -> None:
        client = await self._active_client()
        async with client:
            namespace = await client.get_namespace_index(self.namespace)
            robot_id = self.spec.id
            session = uuid.uuid4().hex[:12]
            paired = await _has_node(client, ua.NodeId(EPOCH, namespace))
            io = SubscriptionIO(client, namespace, robot_id, self.robots.ids, self.driver.status_seq + 1, session, self.epochs, paired)
            names = [f"{robot_id}_{tag}" for tag in ("xgoal", "ygoal", "status", "agent")]
            names += [f"{other}_{tag}" for other in self.robots.ids for tag in PEER_TAGS]
            names += [EPOCH, ROLE] if paired else []
            subscription = await client.create_subscription(50, io)
            await subscription.subscribe_data_change([client.get_node(ua.NodeId(name, namespace)) for name in names], queuesize=1)
            await self._register(client, namespace, io)
            self.connections += 1
            self.connected.set()
            log.info("robot %s: connected to %s, registered and accepted", robot_id, self.endpoint)
            loop = ControlLoop(self.driver, io, self.clock, self.cycle)
            watchdog = asyncio.ensure_future(self._watch(client, io))
            driving = asyncio.ensure_future(loop.run())
            try:
                done, _ = await asyncio.wait({watchdog, driving}, return_when=asyncio.FIRST_COMPLETED)
                for task in done:
                    task.result()  # raises the failure that ended the session
            finally:
                for task in (watchdog, driving):
                    task.cancel()
                self.driver.v = self.driver.w = 0.0  # disconnected: the robot stands still

    async def _register(self, client: Client, namespace: int, io: SubscriptionIO) -> None:
        """Write the registration and wait for the runtime's answer; AgentError if it refuses."""
        robot_id = self.spec.id
        registration = Registration(
            id=robot_id, name=self.spec.name, hardware=sorted(item.value for item in self.spec.hardware),
            host=socket.gethostname(), pid=os.getpid(), software=f"softplc {__version__}", session=io.session,
        )
        try:
            await client.get_node(ua.NodeId(f"{robot_id}_agent", namespace)).write_value(
                ua.DataValue(ua.Variant(registration.encode(), ua.VariantType.String)))
        except ua.UaStatusCodeError as error:
            if error.code in (ua.StatusCodes.BadNodeIdUnknown, ua.StatusCodes.BadNodeIdInvalid):
                raise AgentError(f"the runtime at {self.endpoint} has no tag {robot_id}_agent: robot {robot_id} is not in its "
                                 "robots.yaml, or its robot template lacks the remote-robot tags (docs/robots.md)") from None
            if error.code == ua.StatusCodes.BadInvalidState:  # the standby of a redundant pair: find the active
                raise Unanswered(f"{self.endpoint} is not the active member of its pair") from None
            if error.code == ua.StatusCodes.BadUserAccessDenied:
                who = f"user {self.credentials.user!r}" if self.credentials.user else "an anonymous session"
                raise AgentError(f"{who} may not write {robot_id}_agent at {self.endpoint}: a robot agent logs in as a user "
                                 f"with the operator role (softplc users add {robot_id} --role operator)") from None
            raise
        try:
            await within(ANSWER_TIMEOUT, io.answered.wait())
        except asyncio.TimeoutError:
            raise Unanswered(f"no answer to the registration within {ANSWER_TIMEOUT:g} s") from None
        assert io.answer is not None
        if not io.answer.accepted:
            raise AgentError(f"the runtime at {self.endpoint} refused robot {robot_id}: {io.answer.reason}")

    async def _watch(self, client: Client, io: SubscriptionIO) -> None:
        """End the session when the connection dies even if no write notices it, or its member stops being the active."""
        while True:
            await asyncio.sleep(1.0 if not io.paired else 0.2)
            await client.check_connection()
            if io.paired and ROLE in io.values and not io.obeyed():
                raise Unanswered(f"{client.server_url.geturl()} is no longer the active of its pair "
                                 f"({io.values.get(ROLE)}, epoch {io.values.get(EPOCH)})")

    async def _active_client(self) -> Client:
        """A client of the pair's active (ServiceLevel ≥ 200), else of the first endpoint that answers (alone: the one)."""
        if len(self.endpoints) == 1:
            self.endpoint = self.endpoints[0]
            return await self._client()
        fallback: Client | None = None
        for endpoint in self.endpoints:
            client = await self._client(endpoint)
            try:
                await client.connect()
                level = await client.get_node(ua.NodeId(ua.ObjectIds.Server_ServiceLevel)).read_value()
            except Exception:  # that member is down: try the other
                client.disconnect_socket()
                continue
            await client.disconnect()
            if isinstance(level, int) and level >= 200:
                self.endpoint = endpoint
                return client
            fallback = fallback or client
        if fallback is None:
            raise ConnectionError(f"no member of the pair answers ({', '.join(self.endpoints)})")
        raise Unanswered(f"no member of the pair is active now ({', '.join(self.endpoints)})")

    async def _client(self, endpoint: str | None = None) -> Client:
        credentials = self.credentials
        client = Client(endpoint or self.endpoint, timeout=4)
        if credentials.user:
            client.set_user(credentials.user)
            client.set_password(credentials.password or "")
        if credentials.certificate is not None and credentials.private_key is not None:
            await _secure(client, credentials, user_login=not credentials.user)
        return client


async def _secure(client: Client, credentials: Credentials, *, user_login: bool) -> None:
    """A signed (and encrypted) channel with the robot's certificate; optionally log in with it."""
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    assert credentials.certificate is not None and credentials.private_key is not None
    certificate, key = str(credentials.certificate), str(credentials.private_key)
    uri = _application_uri(credentials.certificate)
    if uri:
        client.application_uri = uri  # the server checks it against the certificate
    if credentials.security != "None":
        mode = ua.MessageSecurityMode.SignAndEncrypt if credentials.security.endswith("SignAndEncrypt") else ua.MessageSecurityMode.Sign
        await client.set_security(SecurityPolicyBasic256Sha256, certificate, key, mode=mode)
    if user_login:
        await client.load_client_certificate(certificate)
        await client.load_private_key(key)


async def _has_node(client: Client, node_id: ua.NodeId) -> bool:
    """Whether the server has this node (a redundant pair's member has `_sys.redundancy.epoch`)."""
    try:
        await client.get_node(node_id).read_browse_name()
    except ua.UaStatusCodeError:
        return False
    return True


def _application_uri(path: Path) -> str:
    """The URI in a certificate's subject alternative names ('' if none)."""
    from cryptography import x509

    data = path.read_bytes()
    certificate = x509.load_pem_x509_certificate(data) if data.startswith(b"-----") else x509.load_der_x509_certificate(data)
    try:
        names = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return ""
    uris = names.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else ""


def _login_hint(status: str, credentials: Credentials) -> str:
    if status == "BadUserAccessDenied":
        if credentials.user:
            return "wrong user name or password (or too many failed logins from this computer: wait a minute)"
        return "the runtime does not let this certificate log in: add its user (softplc users add NAME --certificate ...)"
    if status.startswith("BadCertificate") or status == "BadSecurityChecksFailed":
        return "the runtime does not trust this certificate (softplc opcua trust FINGERPRINT on its machine)"
    return "the runtime does not accept this identity (anonymous sessions may be off: give --user)"


def _describe(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return text if len(text) < 200 else text[:200] + "..."
