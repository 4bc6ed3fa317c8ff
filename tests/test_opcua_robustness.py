"""Misbehaving OPC UA peers never stall the scan or other clients: garbage bytes, absurd frame
sizes, half-sent frames, and a subscribed client that vanishes without closing."""

from __future__ import annotations

import asyncio
import os
import struct

import pytest
import pytest_asyncio
from asyncua import ua

from tests.opcua_support import client_for, running_plant, wait_until

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with running_plant(tmp_path_factory.mktemp("opcua-robust"), security=("None",)) as (runtime, server):
        yield runtime, server


def _port(server) -> int:
    return int(server.endpoint.rsplit(":", 1)[1].split("/", 1)[0])


async def _scan_advances(runtime, cycles: int = 5) -> None:
    start = runtime.tasks[0].stats.cycles
    await wait_until(lambda: runtime.tasks[0].stats.cycles >= start + cycles, timeout=2)


async def _other_client_works(server) -> None:
    async with client_for(server, "operator") as client:
        ns = await client.get_namespace_index("urn:softplc:tags")
        assert await client.get_node(ua.NodeId("s1", ns)).read_value() == "hello"


GARBAGE = {
    "random bytes": os.urandom(512),
    "unknown message type": b"XYZF" + struct.pack("<I", 16) + os.urandom(8),
    "frame claims 100 MB": b"MSGF" + struct.pack("<I", 100_000_000) + os.urandom(64),
    "hello with impossible size": b"HELF" + struct.pack("<I", 4),
    "secure message without a channel": b"MSGF" + struct.pack("<I", 40) + os.urandom(32),
}


@pytest.mark.parametrize("payload", list(GARBAGE.values()), ids=list(GARBAGE))
async def test_garbage_is_refused_and_nobody_else_notices(plant, payload: bytes) -> None:
    runtime, server = plant
    reader, writer = await asyncio.open_connection("127.0.0.1", _port(server))
    writer.write(payload)
    await writer.drain()
    await _scan_advances(runtime)
    await _other_client_works(server)
    writer.close()
    # The server never keeps a connection it refused, or one its peer closed.
    await wait_until(lambda: len(server.server.bserver.clients) == 0, timeout=5)


async def test_half_sent_frame_does_not_block_others(plant) -> None:
    runtime, server = plant
    reader, writer = await asyncio.open_connection("127.0.0.1", _port(server))
    writer.write(b"HELF" + struct.pack("<I", 60) + b"\x00" * 10)  # promises 52 more bytes, never sends
    await writer.drain()
    await _scan_advances(runtime)
    await _other_client_works(server)
    writer.close()


async def test_subscribed_client_vanishing_without_goodbye_stalls_nothing(plant) -> None:
    runtime, server = plant
    vanishing = client_for(server, "viewer")
    await vanishing.connect()
    ns = await vanishing.get_namespace_index("urn:softplc:tags")
    subscription = await vanishing.create_subscription(1, None)
    await subscription.subscribe_data_change([vanishing.get_node(ua.NodeId("count", ns))])
    vanishing.uaclient.protocol.transport.abort()  # like a pulled cable: no CloseSession, no FIN handshake
    await _scan_advances(runtime, 20)
    received: list[int] = []

    class Handler:
        def datachange_notification(self, node, value, data) -> None:
            received.append(value)

    async with client_for(server, "operator") as client:
        other = await client.create_subscription(1, Handler())
        await other.subscribe_data_change([client.get_node(ua.NodeId("count", ns))])
        await wait_until(lambda: len(received) >= 10)
    try:  # stop the dead client's own background tasks; the server is not told anything new
        await asyncio.wait_for(vanishing.disconnect(), 2)
    except Exception:
        pass


async def test_register_server_is_refused_without_a_session(plant) -> None:
    _, server = plant
    client = client_for(server, timeout=2)
    await client.connect_socket()
    try:
        await client.send_hello()
        await client.open_secure_channel()
        registered = ua.RegisteredServer(ServerUri="urn:intruder", IsOnline=True, DiscoveryUrls=["opc.tcp://evil:4840"])
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await client.uaclient.register_server(registered)
        assert refused.value.code == ua.StatusCodes.BadServiceUnsupported
        servers = await client.find_servers()
        assert all(entry.ApplicationUri != "urn:intruder" for entry in servers)
    finally:
        client.disconnect_socket()
