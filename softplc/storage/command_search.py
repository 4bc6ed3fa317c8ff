"""A store searched for a command (audit.query, alarms.journal): what was recorded a moment ago
included, off the event loop, and a store that is down answered as a refusal, not a crash."""

from __future__ import annotations

from typing import Any, Protocol, TypeVar

from softplc.core.clock import Clock
from softplc.core.commands import CommandRefused
from softplc.storage.database import driver_errors

Query = TypeVar("Query", contravariant=True)


class Searchable(Protocol[Query]):
    """A recorder that queues rows for a batch writer and searches what was committed."""

    def flush(self, timeout: float = 30.0) -> bool: ...

    def search(self, query: Query) -> list[Any]: ...


async def search_for_command(clock: Clock, store: Searchable[Query], query: Query, what: str) -> list[Any]:
    """The rows of `store` matching `query`; raises CommandRefused naming `what` ("the audit trail") if it is down."""
    # Rows recorded a moment ago are still queued: commit them first, off the event loop.
    await clock.run_blocking(store.flush, 10.0)
    try:
        return await clock.run_blocking(store.search, query)
    except driver_errors() as error:  # the store is down (a PostgreSQL restart): say so, keep running
        raise CommandRefused(f"{what} cannot be read now: {str(error).strip() or type(error).__name__}") from None
