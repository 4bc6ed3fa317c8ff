"""Clocks: the discrete-event SimClock (order, speed), RealClock guarantees, clock helpers."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from softplc.core.clock import RealClock, SimClock, wait_for


async def driven(clock: SimClock) -> asyncio.Task[None]:
    return asyncio.create_task(clock.drive())


async def test_sim_clock_wakes_in_deadline_order_ties_in_request_order() -> None:
    clock = SimClock()
    driver = await driven(clock)
    woken: list[tuple[float, str]] = []

    async def sleeper(name: str, deadline: float) -> None:
        await clock.sleep_until(deadline)
        woken.append((clock.now(), name))

    await asyncio.gather(
        sleeper("c", 3.0), sleeper("a", 1.0), sleeper("tie1", 2.0), sleeper("tie2", 2.0), sleeper("b", 1.5)
    )
    driver.cancel()
    assert woken == [(1.0, "a"), (1.5, "b"), (2.0, "tie1"), (2.0, "tie2"), (3.0, "c")]


async def test_sim_time_stands_still_while_work_is_ready_and_never_runs_backwards() -> None:
    clock = SimClock()
    driver = await driven(clock)
    await clock.sleep(5.0)
    assert clock.now() == 5.0
    for _ in range(100):  # busy work without waiting on the clock: time does not move
        await asyncio.sleep(0)
    assert clock.now() == 5.0
    await clock.sleep_until(1.0)  # a deadline in the past returns at once, at the present
    assert clock.now() == 5.0
    assert clock.wall() - clock.now() == pytest.approx(1_767_225_600.0)  # a fixed epoch: reproducible
    driver.cancel()


async def test_cancelled_sleepers_do_not_hold_time_back() -> None:
    clock = SimClock()
    driver = await driven(clock)
    early = asyncio.create_task(clock.sleep_until(1.0))
    await asyncio.sleep(0)
    early.cancel()
    await clock.sleep_until(2.0)
    assert clock.now() == 2.0
    driver.cancel()


async def test_drive_until_stops_at_the_limit() -> None:
    clock = SimClock()
    sleeper = asyncio.create_task(clock.sleep_until(10.0))
    await clock.drive(until=4.0)
    assert clock.now() == 4.0 and not sleeper.done()
    sleeper.cancel()


async def test_sockets_are_served_while_simulated_time_runs_and_polling_is_restored_after() -> None:
    # As fast as possible the loop is never idle: I/O is polled every few turns, not every one.
    clock = SimClock()
    loop = asyncio.get_running_loop()
    selector = loop._selector  # type: ignore[attr-defined]
    answers: list[bytes] = []

    async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.write(await reader.readline())
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(echo, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]

    async def ticking() -> None:  # keeps simulated time running: the loop always has a turn ready
        while True:
            await clock.sleep(0.001)

    async def client() -> None:
        for index in range(20):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            writer.write(b"ping %d\n" % index)
            answers.append(await reader.readline())
            writer.close()

    driver = asyncio.create_task(clock.drive())
    ticker = asyncio.create_task(ticking())
    await asyncio.sleep(0)
    assert "select" in vars(selector)  # the sparse poll is in place while time runs
    async with asyncio.timeout(10):
        await client()
    assert answers == [b"ping %d\n" % index for index in range(20)] and clock.now() > 0
    ticker.cancel()
    driver.cancel()
    await asyncio.gather(driver, ticker, return_exceptions=True)
    assert "select" not in vars(selector)  # the loop's own poll again
    server.close()
    await server.wait_closed()


async def test_sim_clock_with_speed_runs_about_n_times_real_time() -> None:
    """Bounded check, not a timing goal: never faster than speed N, not grossly slower."""
    clock = SimClock(speed=20)
    driver = await driven(clock)
    started = time.monotonic()
    for k in range(1, 41):  # 2 simulated seconds in 50 ms steps
        await clock.sleep_until(k * 0.05)
    wall = time.monotonic() - started
    driver.cancel()
    assert clock.now() == 2.0
    assert wall >= 2.0 / 20 * 0.95  # a deadline is never released before its real-time moment
    assert wall < 2.0 / 20 + 2.0


async def test_sim_clock_with_speed_notices_an_earlier_new_sleeper() -> None:
    clock = SimClock(speed=1.0)
    driver = await driven(clock)
    far = asyncio.create_task(clock.sleep_until(30.0))  # would hold the driver for 30 real seconds
    await asyncio.sleep(0.01)
    started = time.monotonic()
    await clock.sleep_until(0.1)
    assert time.monotonic() - started < 5.0 and clock.now() == 0.1
    far.cancel()
    driver.cancel()


def test_speed_must_be_positive() -> None:
    with pytest.raises(ValueError):
        SimClock(speed=0)


async def test_run_blocking_inline_on_sim_and_in_a_thread_on_real_time() -> None:
    sim = SimClock()
    assert await sim.run_blocking(threading.get_ident) == threading.get_ident()
    real = RealClock()
    assert await real.run_blocking(threading.get_ident) != threading.get_ident()
    # the loop stays free while blocking work runs in the executor
    ticks = 0

    async def ticker() -> None:
        nonlocal ticks
        while True:
            ticks += 1
            await asyncio.sleep(0.005)

    task = asyncio.create_task(ticker())
    await real.run_blocking(time.sleep, 0.1)
    task.cancel()
    assert ticks >= 3


async def test_real_clock_never_wakes_before_the_deadline() -> None:
    clock = RealClock()
    for offset in (0.0005, 0.002, 0.011):
        deadline = clock.now() + offset
        await clock.sleep_until(deadline)
        assert clock.now() >= deadline
    assert abs(clock.wall() - time.time()) < 0.5


async def test_wait_for_measures_its_timeout_on_the_clock() -> None:
    clock = SimClock()
    driver = await driven(clock)
    never = asyncio.get_running_loop().create_future()
    with pytest.raises(TimeoutError):
        await wait_for(clock, never, 60.0)  # a simulated minute: no real waiting
    assert clock.now() == 60.0 and never.cancelled()

    async def answer() -> int:
        await clock.sleep(1.0)
        return 42

    assert await wait_for(clock, answer(), 5.0) == 42
    assert clock.now() == 61.0
    driver.cancel()


async def test_real_clock_holds_background_sleepers_back_for_a_due_scan_cycle() -> None:
    """A sleeper waking within `guard` of the scan engine's release runs after that cycle."""
    clock = RealClock(guard=0.002)
    release = clock.now() + 0.2
    engine = asyncio.create_task(clock.sleep_until_release(release))
    await asyncio.sleep(0)
    early = asyncio.create_task(clock.sleep_until(release - 0.15))  # well before the guard
    late = asyncio.create_task(clock.sleep_until(release - 0.001))  # inside the guard
    after = asyncio.create_task(clock.sleep_until(release + 0.001))  # after the release
    await asyncio.wait_for(early, timeout=5)
    assert clock.now() < release  # not held back
    await asyncio.wait_for(engine, timeout=5)
    while clock.now() <= release + 0.0015:  # past both deadlines while the cycle "runs"
        await asyncio.sleep(0.0005)  # (not the clock: it would hold this sleeper back too)
    assert not late.done() and not after.done()
    clock.cycle_done()
    await asyncio.wait_for(asyncio.gather(late, after), timeout=5)
    # with no release pending, nothing is held back
    await asyncio.wait_for(clock.sleep_until(clock.now() + 0.001), timeout=5)


async def test_real_clock_spin_adapts_to_the_loops_timer_lateness() -> None:
    clock = RealClock(spin=0.0015, max_spin=0.004)
    for _ in range(5):
        await clock.sleep_until_release(clock.now() + 0.006)  # the scan engine's precise sleep
        clock.cycle_done()
    assert 0.0005 <= clock.spin <= 0.004


async def test_a_background_sleeper_is_not_spun_for() -> None:
    # A background sleeper (a robot's cycle, a poll) wakes on the loop's timer: it costs no CPU while
    # it waits. Only the scan engine's release spins its last stretch; when every sleeper did, a 4 ms
    # wait took 24-42 % of the thread's time here (3-6 % now).
    clock = RealClock(spin=0.002, max_spin=0.004)
    cpu, wall = time.thread_time(), time.monotonic()
    for _ in range(25):
        await clock.sleep(0.004)
    assert (time.thread_time() - cpu) / (time.monotonic() - wall) < 0.12


async def test_a_zero_sleep_on_the_real_clock_lets_others_run() -> None:
    clock = RealClock()
    ran = []

    async def other() -> None:
        ran.append(True)

    task = asyncio.create_task(other())
    await clock.sleep(0)
    assert ran == [True]
    await task

