"""The active's lease renewals, in a thread of their own: a busy event loop does not lose the lease.

The scan, the servers and a big sync share one event loop; a cycle of a very large plant, or a
starved machine, can hold it for longer than the lease. Renewing from that loop would let etcd
expire the lease of a runtime that is merely busy — and the pair would fail over to and fro. So
the active renews from a thread with its own loop and its own etcd client, and extends the
plant's ACTIVE term itself (`RoleHolder.renew`: one assignment of an immutable term, safe from
another thread). A frozen process freezes this thread too: it stops renewing, and the standby
takes over as it should. The event loop reads what happened (`lost`, `error`) at its pace.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable

from softplc.adapters.redundancy.coordinator import Coordinator, CoordinatorUnreachable
from softplc.core.plant_role import RoleHolder

log = logging.getLogger(__name__)


class LeaseKeeper:
    """Renews one lease every `period` seconds from its own thread, extending the role's term."""

    def __init__(self, coordinator: Coordinator, lease_id: int, role: RoleHolder, now: Callable[[], float],
                 margin: Callable[[float], float], period: float) -> None:
        self.endpoints = coordinator.endpoints
        self.key = coordinator.key.decode()
        self.lease_seconds = coordinator.lease_seconds
        self.timeout = coordinator.timeout
        self.lease_id = lease_id
        self.role = role
        self.epoch = role.epoch  # the term it renews: never another one
        self.now = now
        self.margin = margin
        self.period = period
        self.lost = False  # etcd answered that the lease is gone
        self.error = ""  # the last renewal's failure ('' after a success)
        self.renewals = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="redundancy-lease", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()

    def _run(self) -> None:
        asyncio.run(self._renew_forever())

    async def _renew_forever(self) -> None:
        coordinator = Coordinator(self.endpoints, self.key, self.lease_seconds, timeout=self.timeout)
        coordinator.adopt(self.lease_id)
        try:
            while not self._stop.is_set():
                sent = self.now()
                try:
                    ttl = await coordinator.renew()
                except CoordinatorUnreachable as error:
                    self.error = str(error)
                else:
                    self.error = ""
                    if ttl <= 0:
                        self.lost = True
                        return
                    self.renewals += 1
                    self.role.renew(sent + ttl - self.margin(ttl), self.epoch)
                await asyncio.sleep(max(0.0, sent + self.period - self.now()))
        finally:
            await coordinator.close()
