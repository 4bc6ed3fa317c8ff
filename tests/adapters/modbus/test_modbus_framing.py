"""Framing: a corrupt frame closes its connection at once; the client's next connection is answered.

Raw sockets send each kind of corrupt frame; a pymodbus client and mbpoll (through a gateway that
keeps one connection to the server, as SCADA drivers and Modbus gateways do) show what a real
client sees: one lost request, then answers again at once (before: ~23 requests unanswered).
"""

from __future__ import annotations

import asyncio
import logging
import random
import re
import struct
import time

import pytest
from modbus_helpers import DOUBLER_PLANT as PLANT
from modbus_helpers import mbap, mbpoll_path, polled, raw_request, start_plant, stop_plant, value_of
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from softplc.adapters.modbus.connections import FRAME_TIMEOUT
from softplc.adapters.modbus.framing import FrameBuffer, FramingError

CONNECTIONS_LOGGER = "softplc.adapters.modbus.connections"
BOUND = 1.0  # s: "at once", with room for a loaded machine (the close takes well under 10 ms)


def random_garbage(seed: int) -> bytes:
    """Random bytes that are certainly not a Modbus TCP frame (checked with the framing rules)."""
    rng = random.Random(seed)
    data = bytes(rng.getrandbits(8) for _ in range(rng.randint(8, 300)))
    frames = FrameBuffer()
    frames.feed(data)
    with pytest.raises(FramingError):
        frames.next_frame()
    return data


CORRUPT = {
    "protocol id 0x1234": b"\x00\x01\x12\x34\x00\x06\x01\x03\x00\x00\x00\x01",
    "protocol id 1, nothing after it": b"\x00\x01\x00\x01",
    "length field 0": b"\x00\x01\x00\x00\x00\x00\x01\x03",
    "length field 1 (no function code)": b"\x00\x01\x00\x00\x00\x01\x01",
    "length field 255 (a 261-byte frame)": mbap(1, 1, struct.pack(">BHHB", 16, 0, 124, 248) + b"\0" * 248),
    "length field 0xffff": b"\x00\x01\x00\x00\xff\xff\x01\x03",
    "an HTTP request": b"GET / HTTP/1.1\r\nHost: plc\r\n\r\n",
    "a TLS ClientHello": bytes.fromhex("160301002a0100002603035a5b"),
    **{f"random bytes (seed {seed})": random_garbage(seed) for seed in range(4)},
}


@pytest.fixture
async def plant(tmp_path):
    running = await start_plant(tmp_path, PLANT)
    yield running
    await stop_plant(running)


def read_counter(plant, transaction: int) -> bytes:
    return mbap(transaction, 1, struct.pack(">BHH", 4, plant.address("counter"), 2))


async def closed_by_server(reader: asyncio.StreamReader, timeout: float = BOUND) -> bool:
    """True when the server closes the connection within `timeout` (nothing else arrives first)."""
    try:
        return await asyncio.wait_for(reader.read(1), timeout) == b""
    except ConnectionResetError:
        return True
    except asyncio.TimeoutError:
        return False


@pytest.mark.parametrize("corrupt", list(CORRUPT.values()), ids=list(CORRUPT))
async def test_a_corrupt_frame_closes_its_connection_at_once_and_the_next_connection_is_answered(plant, corrupt, caplog):
    caplog.set_level(logging.WARNING, logger=CONNECTIONS_LOGGER)
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(corrupt)
        await writer.drain()
        assert await closed_by_server(reader), "the connection stayed open after a corrupt frame"
    finally:
        writer.close()
    # the client's new connection is answered at once
    answer = await raw_request(plant.port, read_counter(plant, 7), timeout=BOUND)
    assert answer[:2] == b"\x00\x07" and answer[7:9] == b"\x04\x04"
    assert plant.adapter.connections().closed_framing == 1
    lines = [r.getMessage() for r in caplog.records if r.name == CONNECTIONS_LOGGER]
    assert len(lines) == 1 and lines[0].startswith("Modbus TCP: closed the connection from 127.0.0.1:"), lines
    assert "MBAP header" in lines[0]


async def test_a_valid_request_after_a_corrupt_frame_on_the_same_connection_is_not_answered_but_closed(plant):
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(CORRUPT["length field 0"])
        writer.write(read_counter(plant, 2))  # never guessed at: it might be garbage that looks valid
        await writer.drain()
        assert await closed_by_server(reader)
    finally:
        writer.close()


async def test_requests_before_a_corrupt_frame_are_answered_then_the_connection_closes(plant):
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(read_counter(plant, 1) + read_counter(plant, 2) + CORRUPT["protocol id 0x1234"])
        await writer.drain()
        answers = await asyncio.wait_for(reader.readexactly(2 * 13), BOUND)
        assert answers[0:2] == b"\x00\x01" and answers[13:15] == b"\x00\x02"
        assert await closed_by_server(reader)
    finally:
        writer.close()


async def test_pipelined_requests_are_all_answered_in_order(plant):
    # pymodbus alone answered the first of requests arriving together and dropped the others.
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(b"".join(read_counter(plant, transaction) for transaction in range(1, 11)))
        await writer.drain()
        answers = await asyncio.wait_for(reader.readexactly(10 * 13), BOUND)
        assert [int.from_bytes(answers[i : i + 2], "big") for i in range(0, len(answers), 13)] == list(range(1, 11))
        counters = [value_of("I", [int.from_bytes(answers[i + 9 : i + 11], "big"), int.from_bytes(answers[i + 11 : i + 13], "big")])
                    for i in range(0, len(answers), 13)]
        assert counters == sorted(counters)
    finally:
        writer.close()


async def test_a_client_far_ahead_of_the_answers_is_paused_not_dropped(plant):
    # 600 requests (7.2 kB) at once: reading pauses beyond 16 frames and resumes as answers go out.
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(b"".join(read_counter(plant, transaction) for transaction in range(600)))
        await writer.drain()
        answers = await asyncio.wait_for(reader.readexactly(600 * 13), 10.0)
        assert [int.from_bytes(answers[i : i + 2], "big") for i in range(0, len(answers), 13)] == list(range(600))
    finally:
        writer.close()


async def test_a_frame_split_across_packets_is_answered(plant):
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        frame = read_counter(plant, 5)
        for part in (frame[:3], frame[3:8], frame[8:]):  # inside the header, then inside the PDU
            writer.write(part)
            await writer.drain()
            await asyncio.sleep(0.05)
        answer = await asyncio.wait_for(reader.readexactly(13), BOUND)
        assert answer[:2] == b"\x00\x05" and answer[7:9] == b"\x04\x04"
        assert plant.adapter.connections().closed_framing == 0
    finally:
        writer.close()


async def test_a_partial_header_is_closed_by_the_next_request_or_after_the_frame_timeout(plant, caplog):
    caplog.set_level(logging.WARNING, logger=CONNECTIONS_LOGGER)
    # three stray bytes and silence: closed when the frame has not completed within FRAME_TIMEOUT
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(b"\x00\x09\x00")
        await writer.drain()
        started = time.monotonic()
        assert await closed_by_server(reader, FRAME_TIMEOUT + 3.0)
        assert time.monotonic() - started >= FRAME_TIMEOUT - 0.1
    finally:
        writer.close()
    assert "an incomplete frame (3 bytes of an MBAP header) for 2 s" in caplog.text
    # three stray bytes, then a request: not yet recognisable as garbage; the next request shows they are
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(b"\x01\x02\x03")
        writer.write(read_counter(plant, 1))
        await writer.drain()
        assert await closed_by_server(reader)
    finally:
        writer.close()
    assert plant.adapter.connections().closed_framing == 2


async def test_a_client_that_half_closes_after_its_request_gets_the_answer(plant):
    reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
    try:
        writer.write(read_counter(plant, 3))
        writer.write_eof()  # like `nc -N`: request, then FIN
        answer = await asyncio.wait_for(reader.readexactly(13), BOUND)
        assert answer[:2] == b"\x00\x03" and answer[7:9] == b"\x04\x04"
        assert await closed_by_server(reader)
    finally:
        writer.close()


async def test_a_flood_of_corrupt_frames_logs_one_line_per_peer_and_the_scan_goes_on(plant, caplog):
    caplog.set_level(logging.DEBUG, logger=CONNECTIONS_LOGGER)
    counter = plant.address("counter")
    cycles_before = plant.runtime.tasks[0].stats.cycles
    plant.adapter._server.peer_log.interval = 1.0  # the summary after 1 s instead of 10
    frames = list(CORRUPT.values())
    for index in range(60):
        reader, writer = await asyncio.open_connection("127.0.0.1", plant.port)
        writer.write(frames[index % len(frames)])
        await writer.drain()
        assert await closed_by_server(reader)
        writer.close()
        if index % 10 == 0:  # a client polling meanwhile is served
            assert not (await plant.client.read_input_registers(counter, count=2)).isError()
    assert plant.adapter.connections().closed_framing == 60

    def lines() -> list[str]:
        return [r.getMessage() for r in caplog.records if r.name == CONNECTIONS_LOGGER and r.levelno >= logging.INFO]

    def summarised() -> int:
        return sum(int(m.group(1)) for line in lines()
                   if (m := re.match(r"Modbus TCP: (\d+) more framing errors from 127\.0\.0\.1 in the last 1 s \(", line)))

    # the first at once, then one summary per interval for the rest (one, unless the loop took > 1 s)
    await plant.wait_for(lambda: summarised() == 59, timeout=5.0)
    assert lines()[0].startswith("Modbus TCP: closed the connection from 127.0.0.1:") and len(lines()) <= 3, lines()
    assert all(r.levelno == logging.WARNING for r in caplog.records if r.name == CONNECTIONS_LOGGER)
    assert "Traceback" not in caplog.text
    await plant.next_cycles(3)
    assert plant.runtime.tasks[0].stats.cycles >= cycles_before + 3


async def test_a_pymodbus_client_is_answered_right_after_a_corrupt_frame_on_its_connection(plant):
    counter = plant.address("counter")
    client = AsyncModbusTcpClient("127.0.0.1", port=plant.port, timeout=1, retries=0, reconnect_delay=0.1)
    await client.connect()
    try:
        assert not (await client.read_input_registers(counter, count=2)).isError()
        client.ctx.transport.write(CORRUPT["protocol id 0x1234"])  # a bug in the client's own stream
        await plant.wait_for(lambda: not client.connected, timeout=BOUND)  # the server closed it
        # pymodbus reconnects after its reconnect_delay; the next request is answered at once then
        closed_at = time.monotonic()
        while True:
            try:
                response = await client.read_input_registers(counter, count=2)
                if not response.isError():
                    break
            except ModbusException:
                pass
            assert time.monotonic() - closed_at < BOUND, "no answer within 1 s of the close"
            await asyncio.sleep(0.02)
        assert plant.adapter.connections().closed_framing == 1
    finally:
        client.close()


class Gateway:
    """A TCP relay keeping one connection to the server for all its clients (like a Modbus
    gateway or a SCADA driver), reopened when the server closes it; can slip garbage into it."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.upstream: tuple[asyncio.StreamReader, asyncio.StreamWriter] | None = None
        self.inject = b""
        self.upstream_closed = asyncio.Event()
        self.server: asyncio.Server | None = None

    async def start(self) -> int:
        self.server = await asyncio.start_server(self._client, "127.0.0.1", 0)
        return self.server.sockets[0].getsockname()[1]

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while request := await reader.read(300):
                if self.upstream is None or self.upstream[1].is_closing():
                    self.upstream = await asyncio.open_connection("127.0.0.1", self.port)
                up_reader, up_writer = self.upstream
                up_writer.write(self.inject + request)
                self.inject = b""
                header = await up_reader.read(300)
                if not header:  # the server closed the shared connection: this request fails
                    up_writer.close()
                    self.upstream_closed.set()
                    break
                writer.write(header)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            writer.close()

    def close(self) -> None:
        if self.upstream is not None:
            self.upstream[1].close()
        if self.server is not None:
            self.server.close()


async def test_mbpoll_through_a_gateway_is_answered_right_after_a_corrupt_frame(plant):
    gateway = Gateway(plant.port)
    port = await gateway.start()

    async def mbpoll() -> tuple[int, str]:
        process = await asyncio.create_subprocess_exec(
            mbpoll_path(), "-m", "tcp", "-a", "1", "-p", str(port), "-1", "-o", "2", "-t", "3:int", "-B", "-r",
            str(plant.address("counter") + 1), "-c", "1", "127.0.0.1",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT)
        output, _ = await asyncio.wait_for(process.communicate(), 10)
        assert process.returncode is not None
        return process.returncode, output.decode()

    try:
        code, out = await mbpoll()
        assert code == 0 and polled(out), out
        gateway.inject = CORRUPT["length field 0"]
        code, out = await mbpoll()  # this request travels behind the garbage: lost with the connection
        assert code != 0, out
        await asyncio.wait_for(gateway.upstream_closed.wait(), BOUND)
        for _ in range(3):  # from then on every poll is answered, none times out (before: ~23 did)
            code, out = await mbpoll()
            assert code == 0 and int(polled(out)[plant.address("counter") + 1]) > 0, out
        assert plant.adapter.connections().closed_framing == 1
    finally:
        gateway.close()
