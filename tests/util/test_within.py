"""`within` — a timeout that never loses a cancel (asyncio.wait_for on Python 3.11 does: a standby's sync loop outlived its runtime's stop)."""

from __future__ import annotations

import asyncio
import sys

import pytest

from softplc.util.tasks import within


async def _cancelled_as_it_finishes(wait: object) -> str:
    loop = asyncio.get_running_loop()
    future = loop.create_future()

    async def worker() -> str:
        await wait(future)  # type: ignore[operator]
        return "carried on"

    task = asyncio.ensure_future(worker())
    await asyncio.sleep(0)  # the worker waits now
    future.set_result(1)  # what it waits for finishes...
    task.cancel()  # ...as it is told to stop
    try:
        return await task
    except asyncio.CancelledError:
        return "cancelled"


async def test_a_cancel_that_comes_as_the_awaited_thing_finishes_is_kept() -> None:
    assert await _cancelled_as_it_finishes(lambda future: within(5.0, future)) == "cancelled"
    if sys.version_info < (3, 12):  # why `within` exists: asyncio.wait_for drops that cancel here
        assert await _cancelled_as_it_finishes(lambda future: asyncio.wait_for(future, 5.0)) == "carried on"


async def test_a_timeout_cancels_what_was_awaited_and_raises_timeout_error() -> None:
    loop = asyncio.get_running_loop()
    future = loop.create_future()
    with pytest.raises(TimeoutError):
        await within(0.01, future)
    assert future.cancelled()
    assert await within(1.0, asyncio.sleep(0, result=7)) == 7
