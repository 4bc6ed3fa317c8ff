"""A member's life in the pair: stand by (campaign, follow the active) until it takes over; be active until it loses the lease.

Standing by, the member asks etcd every `poll` seconds to make it active ("create the key if
nobody holds it"); while another member holds the key it follows that one over the sync link.
The non-preferred member waits one lease at start-up before its first attempt, so that of two
runtimes started at once the preferred one becomes active.

Active, it renews its lease every quarter lease, from a thread of its own (lease_keeper.py: a
busy event loop must not lose the lease). Each renewal that etcd confirms extends the
plant's ACTIVE term to (the moment the renewal was *sent*) + TTL − margin: etcd counts the lease
from when it received the renewal, later than that, so the term always ends before the lease
can. A member that cannot renew — etcd unreachable, the process frozen, the network cut — is
past its term before anyone else can take the key, and the core fences it at once (no scan, no
outputs, no writes; softplc/core/plant_role.py). If etcd answers again and the lease still lives,
the term resumes; if the lease is gone, the member stands by.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from softplc.adapters.redundancy.coordinator import CoordinatorUnreachable, Holder
from softplc.adapters.redundancy.lease_keeper import LeaseKeeper
from softplc.adapters.redundancy.link import LinkRefused
from softplc.adapters.redundancy.sync_client import SyncClient
from softplc.core.plant_role import PlantRole, RoleTerm

# The adapter (softplc.adapters.redundancy.adapter.RedundancyAdapter), which imports this module.
RedundancyAdapter = Any

log = logging.getLogger(__name__)

RECONNECT = 0.2  # s between two attempts to reach the active's sync link
STARTING_POLL = 0.05  # s between two looks at whether this runtime has started all its adapters
STARTUP_GRACE = 5.0  # s the non-preferred member waits at start-up before it campaigns


def margin(lease: float) -> float:
    """How long before the lease's end the ACTIVE term ends."""
    return max(0.15, 0.2 * lease)


async def live(adapter: RedundancyAdapter) -> None:
    """Stand by and be active, in turn, for the adapter's lifetime."""
    settings = adapter.settings
    if settings.preferred != settings.me.name:
        # Of two members started at once the preferred one becomes active: the other lets it start
        # (a process's start-up takes seconds on a busy machine) before it campaigns itself.
        await stand_by(adapter, grace=max(STARTUP_GRACE, 2.0 * settings.lease_seconds))
    while True:
        await be_active(adapter) if adapter.plant.role.term.role is PlantRole.ACTIVE else await stand_by(adapter)


async def stand_by(adapter: RedundancyAdapter, grace: float = 0.0) -> None:
    """Follow whoever is active; return once this member holds the key (then it is ACTIVE)."""
    plant = adapter.plant
    clock = plant.clock
    campaign_from = clock.now() + grace
    follower: asyncio.Task[None] | None = None
    following = ""
    try:
        while True:
            sent = clock.now()
            # Not before every adapter of this runtime has started: one that holds the event loop
            # while it starts (a journal created on a slow disk) would hold up the new lease's
            # first renewal as well — the lease could end before this member ever renewed it.
            campaigning = sent >= campaign_from and plant.state != "STARTING"
            try:
                holder = await (adapter.coordinator.campaign(adapter.announcement(), clock.now) if campaigning
                                else adapter.coordinator.look())
                adapter.coordinator_answered(True)
            except CoordinatorUnreachable as error:
                adapter.coordinator_answered(False, str(error))
                holder = None
            if holder is not None and holder.mine:
                take_over(adapter, holder)
                return
            if holder is None and following and adapter.coordinator_ok:
                log.info("redundancy: the active's key is gone (its lease ended); %s campaigns", adapter.settings.me.name)
                following = ""
            if grace and (sent >= campaign_from or (holder is not None and holder.epoch)):
                return  # the grace is over (or another member is active already): campaign from the main loop
            active = str(holder.value.get("member", "")) if holder is not None and holder.epoch else ""
            if holder is not None and holder.epoch and active != following:
                adapter.saw_active(holder)
            if active and active != adapter.settings.me.name and (follower is None or follower.done() or active != following):
                if follower is not None:
                    follower.cancel()
                following = active
                follower = asyncio.ensure_future(follow(adapter, active))
            await clock.sleep(adapter.poll)
    finally:
        if follower is not None:
            follower.cancel()
            await asyncio.gather(follower, return_exceptions=True)


async def follow(adapter: RedundancyAdapter, active: str) -> None:
    """Keep a sync link to the active open, reconnecting; a refusal is reported and retried."""
    peer = adapter.settings.peer
    plant = adapter.plant
    # Not before every adapter of this runtime has started: a state carries the adapters' parts
    # (the alarms'), and one arriving before its adapter registered it would be refused as unknown.
    while plant.state == "STARTING":
        await plant.clock.sleep(STARTING_POLL)
    while True:
        client = SyncClient(adapter, adapter.client_context, adapter.peer_fingerprint, peer.sync_address, active)
        try:
            await client.run()
        except LinkRefused as refused:
            adapter.refused(f"sync link to {active}: {refused}")
        except (OSError, asyncio.IncompleteReadError, asyncio.TimeoutError, ConnectionError) as error:
            adapter.peer_changed(f"connecting: {type(error).__name__}")
        adapter.unsynced()
        await adapter.plant.clock.sleep(RECONNECT)


def take_over(adapter: RedundancyAdapter, holder: Holder) -> None:
    """This member holds the key: resume the active's journal and become ACTIVE with the new epoch.

    The term counts from when the lease was asked for (`holder.asked`) and ends a margin before the lease can."""
    plant = adapter.plant
    resumed = plant.replication.take_over() if adapter.mirrored else 0
    settings = adapter.settings
    until = holder.asked + settings.lease_seconds - margin(settings.lease_seconds)
    took_over = adapter.active_name not in ("", settings.me.name)
    plant.role.set(RoleTerm(PlantRole.ACTIVE, holder.epoch, until, active=settings.me.name))
    adapter.became_active(holder.epoch, took_over=took_over, resumed=resumed)


async def be_active(adapter: RedundancyAdapter) -> None:
    """Keep the lease (renewed from a thread, lease_keeper.py); return when it is lost (then this member is FENCED)."""
    plant = adapter.plant
    clock = plant.clock
    settings = adapter.settings
    period = settings.lease_seconds / 4
    lease_id = adapter.coordinator.lease_id
    if lease_id is None:
        lost(adapter, "it holds no lease")
        return
    keeper = LeaseKeeper(adapter.coordinator, lease_id, plant.role, clock.now, margin, period)
    keeper.start()
    try:
        while True:
            await clock.sleep(period)
            if keeper.lost:
                lost(adapter, "its lease has expired (another member may be active now)")
                return
            adapter.coordinator_answered(not keeper.error, keeper.error)
            adapter.publish()  # a lapsed term shows as FENCED at once
    finally:
        keeper.stop()


def lost(adapter: RedundancyAdapter, why: str) -> None:
    """The lease is gone: fence, and stand by from the next loop."""
    plant = adapter.plant
    term = plant.role.term
    log.warning("redundancy: %s lost the active role (epoch %d): %s; fenced, standing by", adapter.settings.me.name, term.epoch, why)
    adapter.coordinator.forget_lease()
    adapter.server.drop("this member is no longer active")
    plant.role.set(RoleTerm(PlantRole.FENCED, term.epoch, active="", detail=adapter.refusal_detail("")))
    adapter.publish()
