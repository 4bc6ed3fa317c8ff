"""The OPC UA adapter: serves every tag of the runtime over OPC UA (asyncua 2.1.0).

Public surface (what other adapters, tools and tests use):

    server = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/"))
    runtime.add_adapter(server); await runtime.start()
    server.endpoint          actual URL, with the real port when 0 was asked for
    server.namespace_uri     "urn:softplc:tags" unless configured (`namespace:`)
    server.namespace_index   its index in this server (clients: `await client.get_namespace_index(uri)`)
    server.node_id("r01_xpos")  → ua.NodeId("r01_xpos", namespace_index); clients build the same
                             NodeId themselves: `ns=<index>;s=<tag name>`
    softplc.adapters.opcua.variant_for(tag_definition, value)  the Variant a client should write

Users and certificates: `softplc.adapters.opcua.UserStore(path).add(name, Role.OPERATOR, password)`,
`softplc.adapters.opcua.Pki(state_dir / "pki").trust(certificate_file)` (the CLI does the same).
Clients (robot agents, tools): `softplc.adapters.opcua.make_client(endpoint, user=…, password=…,
certificate=ensure_client_certificate(dir, name), security="Basic256Sha256_SignAndEncrypt")`.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import time
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any
from urllib.parse import urlparse

from asyncua import Server, ua
from asyncua.common.callback import CallbackType

from softplc import __version__
from softplc.adapters.opcua.address_space import AddressSpaceBuilder, plan_folders, tag_node_id
from softplc.adapters.opcua.browsing import MAX_CONTINUATION_POINTS, SubtypeCachingViewService
from softplc.adapters.opcua.commands import CommandsDoor  # the door to plant.commands
from softplc.adapters.opcua.conditions import AlarmConditions  # Part 9 conditions
from softplc.adapters.opcua.history import MAX_NODES_PER_HISTORY_READ, HistoryProvider, NoHistory, TagHistoryService
from softplc.adapters.opcua.history_capabilities import advertise_history
from softplc.adapters.opcua.history_provider import CommandHistory  # the historian's commands, when it runs
from softplc.adapters.opcua.publisher import Publisher
from softplc.adapters.opcua.redundancy import ServerRedundancy, redundancy_info  # a redundant pair's ServiceLevel
from softplc.adapters.opcua.roles import RolePermissions
from softplc.adapters.opcua.scheduling import ScanGuard
from softplc.adapters.opcua.server_status import ServerStatusClock
from softplc.adapters.opcua.settings import POLICIES, POLICY_NONE, POLICY_TEXT, OpcUaSettings
from softplc.adapters.opcua.standard_nodes import init_server
from softplc.adapters.opcua.transport import ConnectionLimits, GuardedServer
from softplc.adapters.opcua.user_manager import SoftplcUserManager
from softplc.adapters.opcua.writes import MAX_NODES_PER_READ, MAX_NODES_PER_WRITE, TagAttributeService
from softplc.config.yamlsource import ConfigError
from softplc.security.certificates import ClientCertificateValidator, Pki, SecuredChannels
from softplc.security.users import UserStore
from softplc.util.plurals import plural

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

# Under a simulated clock, tag changes reach the address space at most 50 times a (real) second,
# more often than any subscription samples; see publisher.py.
SIMULATED_PUSH_PERIOD = 0.02


class OpcUaServer:
    """Adapter: an asyncua server whose address space mirrors the plant's tag database."""

    name = "opcua"

    def __init__(self, settings: OpcUaSettings | None = None, *, history: HistoryProvider | None = None) -> None:
        self.settings = settings or OpcUaSettings()
        self._given_history = history
        self.history: HistoryProvider = history or NoHistory()  # a historian plugs in here (history.py)
        self.endpoint = self.settings.endpoint
        self.namespace_index = 0
        self.startup_seconds = 0.0  # from start() to listening with every tag in place
        self.node_count = 0
        self.server: Server | None = None
        self.users: UserStore | None = None
        self.pki: Pki | None = None
        self.publisher: Publisher | None = None
        self.writes: TagAttributeService | None = None
        self.user_manager: SoftplcUserManager | None = None
        self.conditions: AlarmConditions | None = None
        self.commands_door: CommandsDoor | None = None
        self.server_clock: ServerStatusClock | None = None
        self.redundancy: ServerRedundancy | None = None
        self._redundancy: dict[str, Any] | None = None

    @property
    def namespace_uri(self) -> str:
        return self.settings.namespace

    def node_id(self, tag: str) -> ua.NodeId:
        """The NodeId of a tag's Variable."""
        return tag_node_id(tag, self.namespace_index)

    # -- lifecycle ------------------------------------------------------------------------

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        started = time.perf_counter()
        self._redundancy = await redundancy_info(plant)
        if self._redundancy is not None:  # each member of a redundant pair serves under its own application URI
            import dataclasses

            self.settings = dataclasses.replace(self.settings, application_uri=str(self._redundancy["application_uri"]))
        settings = self.settings
        try:
            self.users = UserStore(settings.users_path(plant.state_dir))
        except ConfigError as error:
            raise AdapterError(f"OPC UA users file is invalid:\n{error}") from None
        self.pki = Pki(settings.pki_path(plant.state_dir))
        self._secured_channels = SecuredChannels()
        self.guard = ScanGuard.for_plant(plant)
        if self._given_history is None:
            # The historian (started before us, softplc/app/adapters.py) serves its reads as commands.
            self.history = await CommandHistory.connect(plant.commands) or NoHistory()
        self.user_manager = SoftplcUserManager(self.users, settings.anonymous_role)
        server = GuardedServer(
            user_manager=self.user_manager,
            secured=self._secured_channels,
            offer_none=POLICY_NONE in settings.policies,
            guard=self.guard,
            connection_limits=ConnectionLimits(
                max_message_size=settings.max_message_size,
                max_chunk_count=settings.max_chunk_count,
                max_connections_per_peer=settings.max_connections_per_peer,
            ),
        )
        self.server = server
        server.name = f"softplc {plant.name}"
        server.product_uri = "urn:softplc"
        server.manufacturer_name = "softplc"
        server.application_type = ua.ApplicationType.Server
        server.set_endpoint(settings.endpoint)
        # asyncua's 1 s CurrentTime task would make stop() wait up to a second; ServerStatusClock
        # (installed once the server runs) answers reads and subscribers instead.
        server.disable_clock(True)
        iserver = server.iserver
        iserver.allow_remote_admin = False
        iserver.max_pending_activation_seconds = 10.0  # a connection that never logs in is closed
        # A session whose client vanished keeps its subscriptions (fed by every scan) until it
        # times out; clients keep sessions alive anyway, so a minute is plenty.
        iserver.max_session_timeout_ms = 60_000
        # Loading asyncua's standard address space and building ours make ~100 objects a
        # node; the collector's full passes over them meanwhile cost a third of the start-up.
        collecting = gc.isenabled()
        gc.disable()
        try:
            await self._build_server(server, plant)
        finally:
            if collecting:
                gc.enable()
        # A full collection over a big address space pauses the loop for 0.3 s+; the nodes
        # live as long as the server, so move everything so far out of the collector's sight.
        gc.freeze()
        try:
            await server.start()
        except OSError as error:
            await _quiet_stop(server)
            self.server = None
            raise AdapterError(f"OPC UA cannot listen on {settings.host}:{settings.port}: {error.strerror or error}") from None
        self._after_listen(server)
        self.server_clock = ServerStatusClock(server.iserver.aspace, plant.clock)
        await self.server_clock.install()
        self.server_clock.run()
        assert self.publisher is not None
        self.publisher.run()
        self.startup_seconds = time.perf_counter() - started
        log.info("OPC UA serving %s (%s) on %s, ready in %.2f s",
                 plural(len(plant.tags), "tag"), plural(self.node_count, "node"), self.endpoint, self.startup_seconds)

    async def _build_server(self, server: Server, plant: Plant) -> None:
        settings = self.settings
        if plant.clock.simulated:
            # A simulation's start is a good part of its run: the standard nodes come from this
            # machine's cache (made by the first simulation). Unpickled they take ~100 MB more
            # memory than built, which a server running for months need not pay for 0.5 s once.
            await init_server(server)
        else:
            await server.init()
        server.iserver.view_service = SubtypeCachingViewService(server.iserver.aspace)  # Browse without re-walking type trees
        await server.set_application_uri(settings.application_uri)
        await server.set_build_info("urn:softplc", "softplc", "softplc", __version__, __version__, datetime.now(timezone.utc))
        # Advertise the request limits the Write service enforces, so clients split big requests.
        for limit, value in ((ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerRead, MAX_NODES_PER_READ),
                             (ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerWrite, MAX_NODES_PER_WRITE),
                             (ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerHistoryReadData, MAX_NODES_PER_HISTORY_READ)):
            await server.get_node(ua.NodeId(limit)).write_value(ua.Variant(value, ua.VariantType.UInt32))
        await server.get_node(ua.NodeId(ua.ObjectIds.Server_ServerCapabilities_MaxBrowseContinuationPoints)).write_value(
            ua.Variant(MAX_CONTINUATION_POINTS, ua.VariantType.UInt16))
        await advertise_history(server, getattr(self.history, "aggregates", ()), data=not isinstance(self.history, NoHistory))
        self.namespace_index = await server.register_namespace(settings.namespace)
        await self._configure_security(server)
        await self._build_address_space(plant)
        # Alarms & Conditions (softplc/adapters/opcua/conditions.py), Objects/Commands (commands.py)
        self.conditions = await AlarmConditions.install(server, plant, self.namespace_index)
        self.commands_door = await CommandsDoor.install(server, plant.commands, self.namespace_index)
        if self._redundancy is not None:
            self.redundancy = await ServerRedundancy.install(server, plant, self._redundancy)

    async def stop(self) -> None:
        if self.redundancy is not None:
            self.redundancy.stop()
        if self.conditions is not None:
            await self.conditions.stop()
        if self.server_clock is not None:
            await self.server_clock.stop()
        if self.publisher is not None:
            await self.publisher.stop()
        if self.server is not None:
            await _quiet_stop(self.server)
            self.server = None
            if self.user_manager is not None:
                self.user_manager.close()
            # Let the collector have the stopped server's nodes back (a pause no longer matters).
            gc.unfreeze()

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py): sessions, subscriptions, monitored items."""
        if self.server is None:
            return {}
        iserver = self.server.iserver
        subscriptions = list(iserver.subscription_service.subscriptions.values())
        return {
            "sessions": len(iserver._external_sessions),  # asyncua keeps the activated sessions here, no public count
            "subscriptions": len(subscriptions),
            "monitored_items": sum(len(subscription.monitored_item_srv._monitored_items) for subscription in subscriptions),
        }

    def describe(self) -> str:
        settings = self.settings
        policies = ", ".join(POLICY_TEXT[p] for p in settings.policies)
        anonymous = "anonymous read-only" if settings.anonymous_role is not None else "no anonymous access"
        users = len(self.users.entries()) if self.users is not None else 0
        where = self.users.path if self.users is not None else "users file"
        namespace = f"ns={self.namespace_index} {self.namespace_uri}"
        return f"OPC UA on {self.endpoint} ({namespace}; security: {policies}; {anonymous}; {plural(users, 'user')} in {where})"

    # -- parts of start -------------------------------------------------------------------

    async def _configure_security(self, server: Server) -> None:
        settings = self.settings
        assert self.pki is not None
        if settings.secured:
            if settings.certificate is not None and settings.private_key is not None:
                await server.load_certificate(str(settings.certificate))
                await server.load_private_key(str(settings.private_key))
            else:
                host = settings.host
                hosts = [host] if host not in ("0.0.0.0", "::") else []
                # Key generation takes a moment on first start: keep it off the loop.
                own = await asyncio.to_thread(self.pki.own_identity, settings.application_uri, hosts)
                server.iserver.certificate, server.iserver.private_key = own  # what Server.load_certificate/_private_key set
        if POLICY_NONE in settings.policies and not settings.loopback:
            log.warning("OPC UA offers SecurityPolicy None on %s: traffic and passwords are not protected", settings.host)
        server.set_security_policy([POLICIES[p] for p in settings.policies], permission_ruleset=RolePermissions())
        tokens: list[type] = [ua.UserNameIdentityToken]
        if settings.anonymous_role is not None:
            tokens.append(ua.AnonymousIdentityToken)
        if settings.secured:
            tokens.append(ua.X509IdentityToken)
        server.set_identity_tokens(tokens)
        server.iserver.certificate_validator = ClientCertificateValidator(
            self.pki, self._secured_channels, all_secured=POLICY_NONE not in settings.policies
        )

    async def _build_address_space(self, plant: Plant) -> None:
        assert self.server is not None
        iserver = self.server.iserver
        db = plant.tags
        ns = self.namespace_index
        node_ids = {tag.name: tag_node_id(tag.name, ns) for tag in db}
        pace = SIMULATED_PUSH_PERIOD if plant.clock.simulated else 0.0
        self.publisher = Publisher(db, iserver.aspace, node_ids, guard=self.guard, pace=pace)
        self.publisher.start()  # listen first: a change made while we build is pushed after
        builder = AddressSpaceBuilder(iserver.aspace, ns)
        roots = plan_folders((tag.definition for tag in db), self.settings.folder_size)
        await builder.build(roots, {tag.name: tag for tag in db}, historized=self.history.historized)
        self.node_count = builder.node_count
        self.writes = TagAttributeService(iserver.aspace, db, ns)
        iserver.attribute_service = self.writes
        iserver.history_manager = TagHistoryService(iserver, db, ns, self.history, plant.clock.run_blocking)
        # UserAccessLevel per session role: asyncua's attribute service reads without the session.
        self.server.subscribe_server_callback(CallbackType.PostRead, self.writes.user_access_level)

    def _after_listen(self, server: Server) -> None:
        host, port, path = self.settings.parsed_endpoint()
        if server.bserver is not None and port == 0:
            # Asked for any free port: advertise the one we got.
            port = server.bserver.port
            self.endpoint = f"opc.tcp://{host}:{port}{path}"
            server.endpoint = urlparse(self.endpoint)
            for description in server.iserver.endpoints:
                description.EndpointUrl = self.endpoint
                description.Server.DiscoveryUrls = [self.endpoint]


async def _quiet_stop(server: Server) -> None:
    try:
        await server.stop()
    except Exception:
        log.exception("stopping the OPC UA server failed")
