"""The redundancy adapter: this runtime as one member of a hot-standby pair (docs/redundancy.md).

It decides the plant's role with the coordinator (election.py, coordinator.py) and sets it in the
core (`plant.role`), which honours it: a standby scans nothing and refuses writes and actions
naming the active; it feeds the standby from the active's cycle boundaries over the sync link
(sync_server.py, sync_client.py); and it shows all of it as `_sys.redundancy.*` tags (the OPC UA
server reads its ServiceLevel there), figures on /metrics and the `redundancy.status` query.
"""

from __future__ import annotations

import asyncio
import hashlib
import inspect
import json
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from softplc.adapters.redundancy import section as tags
from softplc.adapters.redundancy.coordinator import Coordinator, Holder
from softplc.adapters.redundancy.election import live
from softplc.adapters.redundancy.settings import RedundancySettings
from softplc.adapters.redundancy.sync_server import SyncServer
from softplc.core.commands import Permission
from softplc.core.plant import AdapterError
from softplc.core.plant_role import PlantRole, RoleTerm
from softplc.security.pair_certificates import fingerprint, link_context
from softplc.util.tasks import cancel_and_wait

if TYPE_CHECKING:
    from softplc.adapters.redundancy.sync_client import SyncClient
    from softplc.config.plant import PlantConfig
    from softplc.core.plant import Plant, TaskView

log = logging.getLogger(__name__)

PUBLISH_PERIOD = 0.2  # s between two publications of the _sys.redundancy tags (and an idle active's heartbeat state)


def config_hash(config: PlantConfig) -> str:
    """What both members must share: the file (but `redundancy.member`) and every program's source."""
    raw = json.loads(json.dumps(config.raw, default=str))
    if isinstance(raw.get("redundancy"), dict):
        raw["redundancy"].pop("member", None)
    digest = hashlib.sha256(json.dumps(raw, sort_keys=True).encode())
    for task in config.tasks:
        for program in task.programs:
            try:
                digest.update(inspect.getsource(inspect.getmodule(program.cls) or program.cls).encode())
            except (OSError, TypeError):
                digest.update(program.reference.encode())
    return digest.hexdigest()


class RedundancyAdapter:
    """One member of the pair (see the module docstring)."""

    name = "redundancy"

    def __init__(self, config: PlantConfig, settings: RedundancySettings) -> None:
        self.settings = settings
        self.config_hash = config_hash(config)
        self.poll = max(0.05, min(0.1, settings.lease / 10))
        self.coordinator = Coordinator(settings.endpoints, settings.election_key, settings.lease_seconds,
                                       timeout=max(0.2, min(0.5, settings.lease / 4)))
        self.peer_fingerprint = fingerprint(settings.peer.certificate)
        me, peer = settings.me, settings.peer
        assert me.key is not None
        self.server = SyncServer(self, link_context(me.certificate, me.key, peer.certificate, server=True), self.peer_fingerprint)
        self.client_context = link_context(me.certificate, me.key, peer.certificate, server=False)
        self.plant: Plant = None  # type: ignore[assignment]  # set by start()
        self.active_name = ""
        self.active_value: dict[str, Any] = {}
        self.mirrored = False  # a full state of the active has been applied here since this member last was active
        self.failovers = 0
        self.refusals = 0
        self.peer_text = "starting"
        self.coordinator_ok = False
        self.coordinator_error = ""
        self.started = False
        self._client: SyncClient | None = None
        self._last_capture = 0.0
        self._undo: list[Callable[[], None]] = []
        self._tasks: list[asyncio.Task[Any]] = []

    def describe(self) -> str:
        return (f"redundancy: member {self.settings.me.name} of {', '.join(m.name for m in self.settings.members)}, "
                f"sync link on {self.settings.me.listen or self.settings.me.sync}, etcd at "
                f"{', '.join(f'{h}:{p}' for h, p in self.settings.endpoints)}")

    # -- lifecycle ----------------------------------------------------------------------------

    async def start(self, plant: Plant) -> None:
        self.plant = plant
        me = self.settings.me
        plant.role.member = me.name  # the adapters started after this one make their client ids this member's own
        # Nothing runs as active before the coordinator says so.
        plant.role.set(RoleTerm(PlantRole.STANDBY, 0, detail=f"this runtime ({me.name}) is starting as a member of a "
                                                               "redundant pair and has no role yet: write to the active"))
        await self.coordinator.prepare()  # not on the event loop at the first campaign, under the other adapters' feet
        host, port = me.listen_address
        try:
            await self.server.start(host, port)
        except OSError as error:
            raise AdapterError(f"redundancy: cannot listen for the sync link on {host}:{port}: {error.strerror or error}") from None
        replication = plant.replication
        self._undo.append(replication.on_journal(self.server.send_journal))
        self._undo.append(plant.after_cycle(self._after_cycle, last=True))  # what every adapter left at the boundary
        commands = plant.commands
        self._undo.append(commands.register("redundancy.status", lambda arguments, origin: self.status(), permission=Permission.VIEW,
                                            description="the redundant pair's state"))
        self._undo.append(commands.register("redundancy.servers", lambda arguments, origin: self.servers(), permission=Permission.VIEW,
                                            description="the pair's OPC UA redundancy (for the OPC UA server)"))
        self.started = True
        self.publish()
        self._tasks = [plant.spawn(live(self), "redundancy"), plant.spawn(self._publish_forever(), "redundancy-tags")]

    async def stop(self) -> None:
        plant = self.plant
        was_active = plant is not None and plant.role.is_active()
        if plant is not None:
            term = plant.role.term
            plant.role.set(RoleTerm(PlantRole.FENCED, term.epoch, detail=f"this runtime ({self.settings.me.name}) is stopping"))
        await cancel_and_wait(self._tasks)
        for undo in self._undo:
            undo()
        await self.server.stop()
        if was_active:
            await self.coordinator.resign()  # the standby takes over now, not at the lease's end
        await self.coordinator.close()

    # -- the scan boundary --------------------------------------------------------------------

    def _after_cycle(self, task: TaskView) -> None:
        if self.server.standby is not None:
            self.server.send_cycle(self.plant, task)
            self._last_capture = self.plant.clock.now()

    # -- what the election and the link report --------------------------------------------------

    def announcement(self) -> dict[str, Any]:
        me = self.settings.me
        return {"member": me.name, "sync": me.sync, "opcua": me.opcua, "hmi": me.hmi}

    def coordinator_answered(self, ok: bool, why: str = "") -> None:
        if ok != self.coordinator_ok:
            if ok:
                log.info("redundancy: the coordinator (etcd) answers again")
            else:
                log.warning("redundancy: the coordinator is unreachable: %s", why)
        self.coordinator_ok, self.coordinator_error = ok, why

    def saw_active(self, holder: Holder) -> None:
        member = str(holder.value.get("member", ""))
        if member and member != self.active_name:
            log.info("redundancy: %s is active (epoch %d)", member, holder.epoch)
        self.active_name, self.active_value = member, dict(holder.value)
        term = self.plant.role.term
        if term.role is not PlantRole.ACTIVE:
            self.plant.role.set(RoleTerm(PlantRole.STANDBY, max(term.epoch, holder.epoch), active=member, detail=self.refusal_detail(member)))
        self.publish()

    def following(self, epoch: int, member: str) -> None:
        """The sync link to `member` (epoch) is open: this member is its standby."""
        self.plant.role.set(RoleTerm(PlantRole.STANDBY, epoch, active=member, detail=self.refusal_detail(member)))
        self.peer_changed("syncing")

    def synced(self, client: SyncClient) -> None:
        self._client = client
        if not self.mirrored:
            self.mirrored = True
            log.info("redundancy: %s is in sync with the active, %s", self.settings.me.name, client.active)
        if self.peer_text != "in sync":
            self.peer_changed("in sync")

    def unsynced(self) -> None:
        self._client = None

    def became_active(self, epoch: int, *, took_over: bool, resumed: int) -> None:
        me = self.settings.me.name
        if took_over:
            self.failovers += 1
        log.warning("redundancy: %s is ACTIVE (epoch %d)%s%s", me, epoch,
                    f", taking over from {self.active_name}" if took_over else "",
                    f"; {resumed} acknowledged write(s) resumed" if resumed else "")
        self.active_name, self.active_value = me, self.announcement()
        self.mirrored = False
        self._client = None
        self.peer_changed("waiting for the standby")

    def peer_changed(self, text: str) -> None:
        if text != self.peer_text:
            log.info("redundancy: the peer: %s", text)
        self.peer_text = text
        self.publish()

    def refused(self, text: str) -> None:
        self.refusals += 1
        log.warning("redundancy: refused %s", text)
        self.peer_text = f"refused: {text}"[:200]
        self.publish()

    def refusal_detail(self, active: str) -> str:
        me = self.settings.me.name
        if not active:
            return f"this runtime ({me}) is not the active one of its redundant pair, and no active is known now: try again shortly"
        member = next((m for m in self.settings.members if m.name == active), None)
        where = f" ({member.opcua})" if member is not None and member.opcua else ""
        return f"this runtime ({me}) is the standby of its redundant pair: write to the active, {active}{where}"

    # -- what it shows -------------------------------------------------------------------------

    def _peer_ok(self) -> tuple[bool, float, int]:
        """(peer in sync, age of the last sync in s, states not acknowledged)."""
        now = self.plant.clock.now()
        limit = self.settings.sync_lag_alarm
        if self.plant.role.is_active():
            standby = self.server.standby
            if standby is None:
                return False, 0.0, 0
            age = now - standby.acked_at
            return age <= limit, age, max(0, standby.sent_sequence - standby.acked_sequence)
        client = self._client
        if client is None or client.applied_at is None:
            return False, 0.0, 0
        age = now - client.applied_at
        return age <= limit, age, 0

    def role_text(self) -> str:
        role = self.plant.role
        if role.role is PlantRole.STANDBY and role.epoch == 0 and not self.active_name:
            return "STARTING"
        return role.role.value

    def service_level(self) -> int:
        """OPC UA Part 4 ServiceLevel: ≥ 200 healthy (the active), < 200 degraded (the standby), 1 no data."""
        role = self.role_text()
        ok, _, _ = self._peer_ok()
        if role == PlantRole.ACTIVE.value:
            return 255 if ok else 200
        if role == PlantRole.STANDBY.value:
            return 100 if ok else 50
        return 1

    def publish(self) -> None:
        """Write the `_sys.redundancy.*` tags now (only changes reach subscribers)."""
        plant = self.plant
        if plant is None or not self.started:
            return
        ok, age, lag = self._peer_ok()
        role = self.role_text()
        degraded = role == PlantRole.ACTIVE.value and not (ok and self.coordinator_ok)
        degraded = degraded or (role == PlantRole.STANDBY.value and not (ok and self.coordinator_ok))
        active = next((m for m in self.settings.members if m.name == self.active_name), None)
        plant.tags.commit({
            tags.ROLE: role, tags.MEMBER: self.settings.me.name, tags.ACTIVE: self.active_name,
            tags.EPOCH: plant.role.epoch % 2**32, tags.SERVICE_LEVEL: self.service_level(), tags.PEER: self.peer_text,
            tags.PEER_OK: ok, tags.SYNC_AGE: round(age * 1e3, 1), tags.SYNC_LAG: lag % 2**32,
            tags.FAILOVERS: self.failovers % 2**32, tags.COORDINATOR_OK: self.coordinator_ok, tags.DEGRADED: degraded,
            tags.REFUSED: self.refusals % 2**32, tags.ACTIVE_HMI: active.hmi if active else "",
            tags.ACTIVE_OPCUA: active.opcua if active else "", tags.PEER_HMI: self.settings.peer.hmi,
        })

    async def _publish_forever(self) -> None:
        clock = self.plant.clock
        while True:
            await clock.sleep(PUBLISH_PERIOD)
            if self.plant.role.is_active() and self.server.standby is not None and clock.now() - self._last_capture > PUBLISH_PERIOD:
                self.server.send_cycle(self.plant, None)  # type: ignore[arg-type]  # no cycle ran (no task): a heartbeat state
                self._last_capture = clock.now()
            self.publish()

    def status(self) -> dict[str, Any]:
        ok, age, lag = self._peer_ok()
        return {
            "member": self.settings.me.name, "role": self.role_text(), "epoch": self.plant.role.epoch, "active": self.active_name,
            "service_level": self.service_level(), "peer": self.settings.peer.name, "peer_state": self.peer_text, "peer_ok": ok,
            "sync_age_s": age, "sync_lag": lag, "failovers": self.failovers, "refused": self.refusals,
            "coordinator_ok": self.coordinator_ok, "coordinator_error": self.coordinator_error,
            "members": [{"name": m.name, "opcua": m.opcua, "hmi": m.hmi, "sync": m.sync} for m in self.settings.members],
        }

    def servers(self) -> dict[str, Any]:
        """The OPC UA server's redundancy: Hot, this member's application URI, the set's URIs, the ServiceLevel tag."""
        plant = self.settings.plant
        return {"support": "Hot", "application_uri": f"urn:softplc:{plant}:{self.settings.me.name}",
                "server_uris": [f"urn:softplc:{plant}:{member.name}" for member in self.settings.members],
                "service_level_tag": tags.SERVICE_LEVEL}

    def metrics(self) -> dict[str, Any]:
        if self.plant is None or not self.started:
            return {}
        ok, age, lag = self._peer_ok()
        return {"active": int(self.plant.role.is_active()), "epoch": self.plant.role.epoch, "service_level": self.service_level(),
                "failovers": self.failovers, "refused": self.refusals, "peer_ok": int(ok), "sync_age": age, "sync_lag": lag,
                "coordinator_ok": int(self.coordinator_ok)}
