"""Garbage frames and abrupt disconnects never stall the scan or other Modbus clients."""

from __future__ import annotations

import asyncio
import logging
import random
import socket
import struct

import pytest
from modbus_helpers import DOUBLER_PLANT as PLANT
from modbus_helpers import mbap, raw_request, start_plant, stop_plant, value_of


@pytest.fixture
async def plant(tmp_path):
    running = await start_plant(tmp_path, PLANT)
    yield running
    await stop_plant(running)


def junk_frames(rng: random.Random) -> list[bytes]:
    """A bounded mix of broken traffic."""
    frames = [bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300))) for _ in range(60)]
    frames += [
        b"\x00\x01\x12\x34\x00\x06\x01\x03\x00\x00\x00\x01",  # protocol id 0x1234
        b"\x00\x02\x00\x00\xff\xff\x01\x03",  # claims a 65535-byte frame, then silence
        mbap(3, 1, b"\x41\x00\x00"),  # unknown function code
        mbap(4, 1, b""),  # no function code at all
        mbap(5, 1, b"\x03\x00"),  # truncated FC3
        mbap(6, 1, b"\x10\x00\x00\x00\x7b\xf6"),  # FC16 announcing 246 bytes, sending none
        b"GET / HTTP/1.1\r\nHost: x\r\n\r\n",
    ]
    return frames


async def send_and_vanish(port: int, payload: bytes, *, reset: bool) -> None:
    """Connect, send, and disconnect without waiting for an answer (RST if `reset`)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(payload)
    await writer.drain()
    if reset:
        sock = writer.get_extra_info("socket")
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    writer.close()


async def test_garbage_and_abrupt_disconnects_do_not_stall_scan_or_clients(plant, caplog):
    caplog.set_level(logging.WARNING)
    rng = random.Random(1234)
    port = plant.port
    counter = plant.address("counter")
    cycles_before = plant.runtime.tasks[0].stats.cycles
    healthy_reads = 0
    stop = asyncio.Event()

    async def healthy_client() -> None:
        nonlocal healthy_reads
        while not stop.is_set():
            response = await asyncio.wait_for(plant.client.read_input_registers(counter, count=2, device_id=1), 2.0)
            assert not response.isError()
            healthy_reads += 1
            await asyncio.sleep(0.005)

    async def vandal() -> None:
        frames = junk_frames(rng)
        # one long-lived connection spraying everything
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        for frame in frames:
            writer.write(frame)
            await writer.drain()
        writer.close()
        # many short ones that vanish mid-frame, half with a TCP reset
        for index, frame in enumerate(frames[:40]):
            await send_and_vanish(port, frame[: max(1, len(frame) // 2)], reset=index % 2 == 0)
        # a valid request whose sender never reads the answer
        await send_and_vanish(port, mbap(9, 1, struct.pack(">BHH", 4, counter, 2)), reset=True)

    reader_task = asyncio.create_task(healthy_client())
    await asyncio.wait_for(vandal(), 20.0)
    stop.set()
    await asyncio.wait_for(reader_task, 5.0)
    assert healthy_reads > 0
    # the scan kept running, and the program's counter is still served and moving
    await plant.next_cycles(5)
    assert plant.runtime.tasks[0].stats.cycles > cycles_before + 5
    first = value_of("I", (await plant.client.read_input_registers(counter, count=2, device_id=1)).registers)
    await plant.next_cycles(3)
    assert value_of("I", (await plant.client.read_input_registers(counter, count=2, device_id=1)).registers) > first
    # a brand-new connection is served normally
    answer = await raw_request(port, mbap(11, 1, struct.pack(">BHH", 4, counter, 2)))
    assert answer[7] == 4 and answer[8] == 4  # FC4, 4 data bytes
    # the log says what happened briefly: no tracebacks, no frame dumps, no flood
    noisy = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert "Traceback" not in caplog.text and ">>>>>" not in caplog.text
    assert 0 < len(noisy) <= 10, [r.getMessage() for r in noisy]
    assert all(r.levelno == logging.WARNING for r in noisy), [r.getMessage() for r in noisy]


async def test_unknown_function_code_is_answered_and_the_connection_survives(plant):
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(mbap(1, 1, b"\x41\x00\x00"))
        await writer.drain()
        answer = await asyncio.wait_for(reader.read(64), 2.0)
        assert answer[7:] == b"\xc1\x01"  # 0x80 | 0x41, exception 01 illegal function
        writer.write(mbap(2, 1, struct.pack(">BHH", 4, plant.address("counter"), 2)))
        await writer.drain()
        answer = await asyncio.wait_for(reader.read(64), 2.0)
        assert answer[0:2] == b"\x00\x02" and answer[7] == 4
    finally:
        writer.close()
