"""The coordinator: which member of the pair is active, decided by an etcd lease (aetcd, asyncio).

The active holds the election key `/softplc/PLANT/active` attached to a lease of `lease` seconds
(whole seconds: etcd takes no less; it also raises a TTL below 1.5 × its election timeout, so a
1 s lease needs `--election-timeout` ≤ 600 ms, docs/redundancy.md). Whoever creates the key — one
transaction, "create it if nobody has" — is active, and the key's create revision is its
**epoch**: etcd's revisions only grow, so a newer active always has a greater epoch. The holder
renews its lease; when it stops renewing (killed, frozen, cut off), etcd deletes the key at the
lease's end and the other member's next attempt creates it.

Every call has a timeout well under the lease, and a failing endpoint gives way to the next one.
"""

from __future__ import annotations

import asyncio
import importlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)


class CoordinatorUnreachable(Exception):
    """No endpoint of the coordinator answered in time."""


@dataclass(frozen=True)
class Holder:
    """Who holds the election key: mine or not, the epoch (create revision) and what the holder wrote."""

    mine: bool
    epoch: int
    value: dict[str, Any]
    lease: int
    asked: float = 0.0  # mine: the clock time the lease was asked for (etcd counts it from later), where the term counts from


class Coordinator:
    """One member's view of the election (see the module docstring)."""

    def __init__(self, endpoints: tuple[tuple[str, int], ...], key: str, lease_seconds: int, *, timeout: float) -> None:
        self.endpoints = endpoints
        self.key = key.encode()
        self.lease_seconds = lease_seconds
        self.timeout = timeout
        self._index = 0
        self._client: Any = None
        self._lease: Any = None

    async def prepare(self) -> None:
        """Import the etcd client (gRPC: a tenth of a second, seconds on a busy machine) off the event loop."""
        await asyncio.to_thread(importlib.import_module, "aetcd")

    async def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        """Call a client method on the current endpoint, trying each endpoint once; raises CoordinatorUnreachable."""
        import aetcd

        last: BaseException | None = None
        for _ in range(len(self.endpoints)):
            try:
                if self._client is None:
                    host, port = self.endpoints[self._index]
                    self._client = aetcd.Client(host, port, timeout=self.timeout, connect_wait_timeout=1)
                # Not asyncio.wait_for: it waits for the call to finish cancelling, and a gRPC call
                # stuck on a dead channel may never finish; the member must get on with its life.
                call = asyncio.ensure_future(getattr(self._client, method)(*args, **kwargs))
                done, _ = await asyncio.wait({call}, timeout=self.timeout + 0.1)
                if not done:
                    call.cancel()
                    call.add_done_callback(_consume)
                    raise asyncio.TimeoutError()
                return call.result()
            except (aetcd.ClientError, asyncio.TimeoutError, OSError) as error:
                last = error
                await self._drop_client()
                self._index = (self._index + 1) % len(self.endpoints)
        raise CoordinatorUnreachable(f"etcd at {self._describe()} does not answer: {_describe(last)}")

    async def _drop_client(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            closing = asyncio.ensure_future(client.close())
            done, _ = await asyncio.wait({closing}, timeout=0.5)
            if not done:
                closing.cancel()
            closing.add_done_callback(_consume)

    def _describe(self) -> str:
        return ", ".join(f"{host}:{port}" for host, port in self.endpoints)

    async def campaign(self, value: dict[str, Any], now: Callable[[], float]) -> Holder:
        """Create the key with a fresh lease unless someone holds it; returns the holder (maybe us).

        Who holds it is asked first (one cheap read a poll); only when nobody does is a lease
        granted and the key created — in one transaction, so of two members trying at once one wins.
        `now` stamps the moment the lease is asked for (`Holder.asked`): the read before it may
        have taken its time (a busy machine), and that time is not the lease's.
        """
        held = await self.look()
        if held is not None:
            return held
        from aetcd.client import Transactions

        asked = now()
        lease = await self._call("lease", self.lease_seconds)
        transactions = Transactions()
        succeeded, responses = await self._call(
            "transaction",
            compare=[transactions.create(self.key) == 0],
            success=[transactions.put(self.key, json.dumps(value).encode(), lease=lease)],
            failure=[transactions.get(self.key)],
        )
        if succeeded:
            self._lease = lease
            return Holder(True, int(responses[0].response_put.header.revision), value, int(lease.id), asked)
        try:  # the other member was quicker: this lease holds nothing
            await self._call("revoke_lease", lease.id)
        except CoordinatorUnreachable:
            pass
        found = responses[0] if responses else []
        if not found:  # deleted between the compare and the get: try again next time
            return Holder(False, 0, {}, 0)
        data, kv = found[0]
        return self._holder(data, kv)

    def _holder(self, data: bytes, kv: Any) -> Holder:
        try:
            held = json.loads(data.decode())
        except (ValueError, UnicodeDecodeError):
            held = {}
        mine = self._lease is not None and int(kv.lease) == int(self._lease.id)
        return Holder(mine, int(kv.create_revision), held if isinstance(held, dict) else {}, int(kv.lease))

    async def look(self) -> Holder | None:
        """Who holds the key now (None: nobody), without campaigning."""
        found = await self._call("get", self.key)
        return None if found is None else self._holder(found.value, found)

    async def renew(self) -> float:
        """Keep our lease alive; returns the TTL etcd granted (0: the lease is gone, so is the key)."""
        if self._lease is None:
            return 0.0
        try:
            reply = await self._call("refresh_lease", self._lease.id)
        except CoordinatorUnreachable as error:
            if "lease not found" in str(error):  # etcd answered: the lease is gone
                self._lease = None
                return 0.0
            raise
        ttl = float(getattr(reply, "TTL", 0) or 0)
        if ttl <= 0:
            self._lease = None
        return ttl

    async def resign(self) -> None:
        """Give the key up now (a clean stop): the peer takes over at its next attempt, not at the lease's end."""
        lease, self._lease = self._lease, None
        if lease is not None:
            try:
                await self._call("revoke_lease", lease.id)
            except CoordinatorUnreachable as error:
                log.warning("redundancy: could not give up the active role at once (%s); the peer takes over when the lease ends", error)

    @property
    def lease_id(self) -> int | None:
        return int(self._lease.id) if self._lease is not None else None

    def adopt(self, lease_id: int) -> None:
        """Renew a lease granted through another client (the lease keeper's thread has its own)."""
        self._lease = _LeaseId(lease_id)

    def forget_lease(self) -> None:
        """The lease is lost (it lapsed): the next campaign asks for a new one."""
        self._lease = None

    async def close(self) -> None:
        await self._drop_client()


class _LeaseId:
    """A lease known by its id only (what `refresh_lease` and `revoke_lease` need)."""

    def __init__(self, lease_id: int) -> None:
        self.id = lease_id


def _consume(call: asyncio.Future[Any]) -> None:
    """Fetch an abandoned call's outcome, so asyncio does not report it as never retrieved."""
    if not call.cancelled():
        call.exception()


def _describe(error: BaseException | None) -> str:
    if error is None:
        return "no endpoint"
    if isinstance(error, asyncio.TimeoutError):
        return "timed out"
    text = str(error) or type(error).__name__
    return text.splitlines()[0][:200]
