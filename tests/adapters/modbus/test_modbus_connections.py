"""Connection cap and idle timeout: a peer cannot hold unbounded sockets, a polling SCADA is never cut."""

from __future__ import annotations

import asyncio
import logging
import struct
import textwrap

import pytest
from modbus_helpers import DOUBLER_PLANT as PLANT
from modbus_helpers import mbap, start_plant, stop_plant

from softplc.adapters.modbus.connections import EventReport
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.app.cli import main
from softplc.config import load_config

CONNECTIONS_LOGGER = "softplc.adapters.modbus.connections"


class Peer:
    """A raw TCP client of the plant's Modbus port."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer

    @classmethod
    async def connect(cls, port: int) -> Peer:
        return cls(*await asyncio.open_connection("127.0.0.1", port))

    async def read_counter(self, address: int, transaction: int = 1) -> bytes:
        """FC4 on `address` (2 registers); the answer's PDU."""
        self.writer.write(mbap(transaction, 1, struct.pack(">BHH", 4, address, 2)))
        await self.writer.drain()
        answer = await asyncio.wait_for(self.reader.readexactly(13), 5.0)
        return answer[7:]

    async def closed_by_server(self, timeout: float = 10.0) -> bool:
        """Wait until the server closes or resets the connection; False if it stays open."""
        try:
            data = await asyncio.wait_for(self.reader.read(1024), timeout)
        except ConnectionResetError:
            return True
        except asyncio.TimeoutError:
            return False
        return data == b""

    def close(self) -> None:
        self.writer.close()


async def close_all(peers: list[Peer]) -> None:
    for peer in peers:
        peer.close()
    for peer in peers:
        try:
            await peer.writer.wait_closed()
        except OSError:
            pass


@pytest.fixture
async def small_plant(tmp_path):
    running = await start_plant(tmp_path, PLANT, max_connections=5, idle_timeout=0.0)
    yield running
    await stop_plant(running)


async def test_connections_beyond_max_connections_are_refused_and_the_open_ones_keep_working(small_plant, caplog):
    caplog.set_level(logging.INFO, logger=CONNECTIONS_LOGGER)
    plant, counter = small_plant, small_plant.address("counter")
    peers = [await Peer.connect(plant.port) for _ in range(4)]  # with the plant's client: 5 = the cap
    extra: list[Peer] = []
    try:
        for peer in peers:
            assert (await peer.read_counter(counter))[:2] == b"\x04\x04"
        await plant.wait_for(lambda: plant.adapter.connections().open == 5)
        extra = [await Peer.connect(plant.port) for _ in range(20)]
        assert all(await asyncio.gather(*(peer.closed_by_server() for peer in extra)))
        assert plant.adapter.connections().refused == 20
        # everyone already connected is served as before
        for index, peer in enumerate(peers):
            assert (await peer.read_counter(counter, transaction=index + 2))[:2] == b"\x04\x04"
        assert not (await plant.client.read_input_registers(counter, count=2)).isError()
        # one line for 20 refusals, naming the first peer
        refusals = [r for r in caplog.records if r.name == CONNECTIONS_LOGGER]
        assert len(refusals) == 1 and refusals[0].levelno == logging.WARNING
        assert "refused a connection from 127.0.0.1:" in refusals[0].getMessage() and "max_connections (5)" in refusals[0].getMessage()
        # a slot that frees up is taken by the next client
        peers.pop().close()
        await plant.wait_for(lambda: plant.adapter.connections().open == 4)
        newcomer = await Peer.connect(plant.port)
        peers.append(newcomer)
        assert (await newcomer.read_counter(counter))[:2] == b"\x04\x04"
    finally:
        await close_all(peers + extra)


async def test_a_connection_flood_is_capped_while_the_scan_and_a_polling_client_go_on(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger=CONNECTIONS_LOGGER)
    plant = await start_plant(tmp_path, PLANT)  # default max_connections 64
    counter = plant.address("counter")
    flood: list[Peer] = []
    try:
        assert plant.adapter.settings.max_connections == 64
        cycles_before = plant.runtime.tasks[0].stats.cycles
        for index in range(150):
            peer = await Peer.connect(plant.port)
            if index % 2:  # half of them busy with a request (garbage would be closed at once: test_modbus_framing)
                peer.writer.write(mbap(index, 1, struct.pack(">BHH", 4, counter, 2)))
            flood.append(peer)
        # the polling client connected before the flood is still served
        assert not (await plant.client.read_input_registers(counter, count=2)).isError()
        await plant.wait_for(lambda: plant.adapter.connections().refused >= 150 + 1 - 64, timeout=10.0)
        assert plant.adapter.connections().open <= 64
        await plant.next_cycles(3)
        assert plant.runtime.tasks[0].stats.cycles >= cycles_before + 3
        lines = [r for r in caplog.records if r.name == CONNECTIONS_LOGGER]
        assert len(lines) == 1, [r.getMessage() for r in lines]  # not one line per refused connection
    finally:
        await close_all(flood)
        await stop_plant(plant)


async def test_an_idle_connection_is_closed_and_a_polling_client_is_not(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger=CONNECTIONS_LOGGER)
    plant = await start_plant(tmp_path, PLANT, idle_timeout=1.0)
    counter = plant.address("counter")
    stop = asyncio.Event()
    polls = 0

    async def scada() -> None:  # polls far more often than the idle timeout
        nonlocal polls
        while not stop.is_set():
            assert not (await plant.client.read_input_registers(counter, count=2)).isError()
            polls += 1
            await asyncio.sleep(0.01)

    silent = await Peer.connect(plant.port)
    once = await Peer.connect(plant.port)
    poller = asyncio.create_task(scada())
    try:
        assert (await once.read_counter(counter))[:2] == b"\x04\x04"  # one request, then silence
        assert await silent.closed_by_server()
        assert await once.closed_by_server()
        assert plant.adapter.connections().closed_idle == 2
        # the poller connected before both and was served throughout; it is still connected
        assert polls > 0 and plant.client.connected and not poller.done()
        assert plant.adapter.connections().open == 1
        lines = [r for r in caplog.records if r.name == CONNECTIONS_LOGGER]
        assert len(lines) == 1 and "nothing received for 1 s (idle_timeout)" in lines[0].getMessage()
    finally:
        stop.set()
        await asyncio.wait_for(poller, 5.0)
        await close_all([silent, once])
        await stop_plant(plant)


async def test_event_report_logs_a_burst_in_two_lines(caplog):
    caplog.set_level(logging.INFO, logger=CONNECTIONS_LOGGER)
    report = EventReport(logging.WARNING, "refused %s", "refused %s", "more connections", interval=3600.0)
    for index in range(1000):
        report.note(f"peer {index}")
    report.close()
    assert [r.getMessage() for r in caplog.records] == ["refused peer 0", "refused 999 more connections"]
    assert report.total == 1000
    caplog.clear()
    for index in range(2):  # one more: singular
        report.note(f"peer {index}")
    report.close()
    assert [r.getMessage() for r in caplog.records] == ["refused peer 0", "refused 1 more connection"]


def write_config(tmp_path, modbus: str):
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent(f"""\
        version: 1
        tags:
          a: {{type: int16}}
        servers:
          modbus: {modbus}
          opcua: {{enabled: false}}
        """))
    return path


@pytest.mark.parametrize(("text", "seconds"), [("0", 0.0), ("90", 90.0), ("5min", 300.0), ("2.5s", 2.5)])
def test_idle_timeout_is_a_duration(tmp_path, text, seconds):
    config = load_config(write_config(tmp_path, f"{{idle_timeout: {text}, max_connections: 8}}"))
    settings = ModbusSettings.from_servers(config.servers)
    assert (settings.idle_timeout, settings.max_connections) == (seconds, 8)


@pytest.mark.parametrize(
    ("modbus", "message"),
    [
        ("{port: 0, idle_timeout: soon}", "bad idle_timeout 'soon'"),
        ("{port: 0, idle_timeout: -5}", "bad idle_timeout -5"),
        ("{port: 0, max_connections: 0}", "'max_connections' must be at least 1"),
    ],
)
def test_check_reports_bad_connection_settings_with_their_location(tmp_path, capsys, modbus, message):
    path = write_config(tmp_path, modbus)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:5:" in err and message in err, err
    assert "Traceback" not in err
