"""The live channel under a slow client: caught up or dropped, never buffered without bound.

A raw WebSocket client that stops reading (its socket buffers fill up) must not hold up the
others, must not make the server queue data for it, and is dropped after `drop_after`.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import time
from pathlib import Path

import aiohttp
import pytest
from hmi_support import plant_yaml, receive_until, start_plant, wait_until

from softplc.adapters.hmi.fanout import MAX_QUEUED
from softplc.core.clock import SimClock

pytestmark = pytest.mark.asyncio

BLOBS = 300


async def raw_websocket(host: str, port: int, subscribe: list[str]) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """Open a WebSocket by hand, subscribe, and return the streams (the caller then never reads)."""
    reader, writer = await asyncio.open_connection(host, port)
    sock = writer.get_extra_info("socket")
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # a client on a slow link: its buffer fills soon
    key = base64.b64encode(os.urandom(16)).decode()
    writer.write((f"GET /api/live HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    await writer.drain()
    head = await reader.readuntil(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 101"), head
    payload = json.dumps({"type": "subscribe", "items": subscribe}).encode()
    mask = os.urandom(4)
    masked = bytes(byte ^ mask[index % 4] for index, byte in enumerate(payload))
    length = len(payload)
    header = bytes([0x81]) + (bytes([0x80 | 126]) + length.to_bytes(2, "big") if length >= 126 else bytes([0x80 | length]))
    writer.write(header + mask + masked)
    await writer.drain()
    return reader, writer


async def test_a_client_that_stops_reading_is_not_buffered_for_and_is_dropped(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, text=plant_yaml(blobs=BLOBS), heartbeat=5.0)
    hub = plant.hmi.hub
    hub.drop_after = 4.0
    names = [f"b{index:03d}_text" for index in range(1, BLOBS + 1)]
    stop = asyncio.Event()

    async def churn() -> None:
        # 300 tags of 2 KB changing 20 times a second: ~6 MB/s at the 10/s rate limit.
        round_ = 0
        while not stop.is_set():
            round_ += 1
            plant.drive(**{name: f"{round_:06d}" + "x" * 2000 for name in names})
            await asyncio.sleep(0.05)

    churner = asyncio.create_task(churn())
    try:
        _, slow = await raw_websocket("127.0.0.1", plant.hmi.port, names)
        async with aiohttp.ClientSession() as session, session.ws_connect(plant.url + "api/live") as fast:
            await fast.send_json({"type": "subscribe", "items": ["counter"]})
            slow_client = await wait_until(lambda: next((c for c in hub.clients if c.group and len(c.group.names) == BLOBS), None))
            # The slow client falls behind: the server keeps one set of names for it, not a queue of messages.
            await wait_until(lambda: slow_client.behind_since is not None, timeout=10, message="the slow client behind")
            await asyncio.sleep(2.0)  # 20 updates' worth of changes while it reads nothing
            assert len(slow_client._pending) <= BLOBS and slow_client.queued_bytes <= MAX_QUEUED, (len(slow_client._pending), slow_client.queued_bytes)
            assert slow_client.thinned > 0  # and it is told so (a "thinned" message, once it reads again)
            # Meanwhile the other client keeps getting its updates on time.
            updates, started = 0, time.monotonic()
            while time.monotonic() - started < 1.0:
                message = json.loads((await fast.receive(timeout=2)).data)
                updates += message["type"] == "update"
            assert updates >= 7, updates
            await wait_until(lambda: hub.dropped >= 1 and slow_client not in hub.clients, timeout=10, message="the slow client dropped")
            assert fast.closed is False
        slow.close()
    finally:
        stop.set()
        await churner
        await plant.stop()


async def test_pacing_is_real_time_under_a_fast_simulated_clock(tmp_path: Path) -> None:
    """--sim --speed 50: the plant runs 50 times faster, the browser still gets each value at most 10 times a second."""
    plant = await start_plant(tmp_path, clock=SimClock(speed=50))
    try:
        async with aiohttp.ClientSession() as session, session.ws_connect(plant.url + "api/live") as ws:
            await ws.send_json({"type": "subscribe", "items": ["counter", "_sys.time"]})
            await receive_until(ws, "snapshot")
            updates, counts, times, started = 0, [], 0, time.monotonic()
            while time.monotonic() - started < 2.0:
                message = json.loads((await ws.receive(timeout=2)).data)
                if message["type"] == "update":
                    updates += 1
                    counts += [message["values"]["counter"]] if "counter" in message["values"] else []
                    times += "_sys.time" in message["values"]
        assert counts[-1] - counts[0] > 2000  # 2 s at 50x: 100 simulated seconds of a 10 ms task
        assert 10 <= len(counts) <= 23 and 10 <= times <= 23, (len(counts), times)  # each value ≤ 10 times a second (a burst of two)
        assert updates <= len(counts) + times  # and no message without one of them (the rate bound is the line above)
    finally:
        await plant.stop()


async def test_a_group_that_falls_behind_tells_its_clients_they_are_thinned(tmp_path: Path) -> None:
    """The runtime cannot send every change in time (here: its loop blocked for 0.3 s): the client is told, not silently thinned."""
    plant = await start_plant(tmp_path, heartbeat=0.5)
    try:
        async with aiohttp.ClientSession() as session, session.ws_connect(plant.url + "api/live") as ws:
            await ws.send_json({"type": "subscribe", "items": ["counter"]})
            await receive_until(ws, "snapshot")
            await receive_until(ws, "update")
            group = next(iter(plant.hmi.hub.groups.values()))
            late = group.late
            # A change free to go, then the loop held past a whole period: that update goes out late.
            # The client says a word each time, as a page answers pings: with a heartbeat of 0.5 s,
            # 1.25 s of silence drops it (it was dropped so under load, never told).
            while group.late == late:
                await ws.send_json({"type": "pong"})
                plant.drive(limit=float(group.late + time.monotonic() % 50))
                await asyncio.sleep(0.05)
                time.sleep(0.3)  # on purpose, blocking: the runtime busy elsewhere
            deadline = time.monotonic() + 5
            while (message := await receive_until(ws, lambda m: m["type"] in ("thinned", "ping"), timeout=deadline - time.monotonic()))["type"] == "ping":
                await ws.send_json({"type": "pong"})
            assert message["late"] >= 1 and "could not send every change in time" in message["message"]
    finally:
        await plant.stop()
