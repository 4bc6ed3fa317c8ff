"""Misbehaving OPC UA peers never stall the scan or other clients: garbage bytes, absurd frame
sizes, half-sent frames, oversized chunked messages, connection floods, and a subscribed client
that vanishes without closing."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import struct

import pytest
import pytest_asyncio
from asyncua import ua
from asyncua.ua.ua_binary import struct_from_binary, struct_to_binary, uatcp_to_binary

from softplc.adapters.opcua.settings import DEFAULT_MAX_MESSAGE_SIZE
from softplc.util.peers import PeerLog
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


# -- raw secure conversation (SecurityPolicy None), to send what no client library would ----------

async def _read_frame(reader: asyncio.StreamReader) -> tuple[bytes, bytes]:
    """(message type, body after the 8-byte header) of the next frame."""
    head = await reader.readexactly(8)
    message_type, _, size = struct.unpack("<3scI", head)
    return message_type, await reader.readexactly(size - 8)


class RawChannel:
    """A socket with a Hello and an OpenSecureChannel (None) done, that sends hand-made chunks."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.channel_id = self.token_id = 0
        self.sequence = 1

    @classmethod
    async def open(cls, server) -> RawChannel:
        channel = cls(*await asyncio.open_connection("127.0.0.1", _port(server)))
        channel.writer.write(uatcp_to_binary(ua.MessageType.Hello, ua.Hello(EndpointUrl=server.endpoint)))
        assert (await _read_frame_within(channel.reader, 5))[0] == b"ACK"
        request = ua.OpenSecureChannelRequest(Parameters=ua.OpenSecureChannelParameters(
            RequestType=ua.SecurityTokenRequestType.Issue, SecurityMode=ua.MessageSecurityMode.None_, RequestedLifetime=60_000))
        security = struct_to_binary(ua.AsymmetricAlgorithmHeader(SecurityPolicyURI="http://opcfoundation.org/UA/SecurityPolicy#None"))
        body = security + struct.pack("<II", channel.sequence, 1) + struct_to_binary(request)
        channel.writer.write(b"OPNF" + struct.pack("<II", 12 + len(body), 0) + body)
        message_type, answer = await _read_frame_within(channel.reader, 5)
        assert message_type == b"OPN"
        buffer = ua.utils.Buffer(answer[4:])  # after the channel id
        struct_from_binary(ua.AsymmetricAlgorithmHeader, buffer)
        buffer.read(8)  # sequence header
        response = struct_from_binary(ua.OpenSecureChannelResponse, buffer)
        channel.channel_id = response.Parameters.SecurityToken.ChannelId
        channel.token_id = response.Parameters.SecurityToken.TokenId
        return channel

    def send_chunk(self, chunk_type: bytes, payload: bytes, request_id: int = 7) -> None:
        self.sequence += 1
        body = struct.pack("<IIII", self.channel_id, self.token_id, self.sequence, request_id) + payload
        self.writer.write(b"MSG" + chunk_type + struct.pack("<I", 8 + len(body)) + body)

    async def error_and_close(self) -> ua.ErrorMessage | None:
        """The ERR message the server sent before closing (None if it just closed), or fail."""
        error = None
        while True:
            try:
                message_type, body = await _read_frame(self.reader)
            except asyncio.IncompleteReadError:
                return error
            if message_type == b"ERR":
                error = struct_from_binary(ua.ErrorMessage, ua.utils.Buffer(body))

    def close(self) -> None:
        self.writer.close()


async def test_an_oversized_chunked_message_before_login_closes_the_connection(plant) -> None:
    runtime, server = plant
    channel = await RawChannel.open(server)
    chunk = os.urandom(60_000)
    for _ in range(40):  # 2.4 MB in intermediate chunks (asyncua alone would take 100 MB)
        channel.send_chunk(b"C", chunk)
    await channel.writer.drain()
    error = await asyncio.wait_for(channel.error_and_close(), 5)
    channel.close()
    assert error is not None and error.Error.value == ua.StatusCodes.BadRequestTooLarge
    await _scan_advances(runtime)
    await _other_client_works(server)
    await wait_until(lambda: len(server.server.bserver.clients) == 0, timeout=5)


async def test_a_logged_in_client_may_send_more_but_not_beyond_max_message_size(plant) -> None:
    runtime, server = plant
    async with client_for(server, "operator") as client:
        ns = await client.get_namespace_index("urn:softplc:tags")
        node = client.get_node(ua.NodeId("s1", ns))
        # 100 KB is more than a peer may send before logging in, but fine in a session.
        assert (await client.write_values([node], [ua.Variant("x" * 100_000, ua.VariantType.String)]))[0].is_good()
        await wait_until(lambda: len(runtime.db.value("s1")) == 100_000)
        with pytest.raises((ConnectionError, ua.UaError, TimeoutError)):
            await client.write_values([node], [ua.Variant("y" * (DEFAULT_MAX_MESSAGE_SIZE + 1), ua.VariantType.String)])
        await wait_until(lambda: len(server.server.bserver.clients) == 0, timeout=5)
        assert runtime.db.value("s1").startswith("x")
        with contextlib.suppress(Exception):  # the server already closed the connection
            await client.disconnect()
    async with client_for(server, "operator") as other:  # the server still serves; put s1 back
        await other.write_values([other.get_node(ua.NodeId("s1", ns))], [ua.Variant("hello", ua.VariantType.String)])
    await wait_until(lambda: runtime.db.value("s1") == "hello")


def _warnings(caplog: pytest.LogCaptureFixture, text: str) -> list[str]:
    return [record.getMessage() for record in caplog.records if record.levelno >= logging.WARNING and text in record.getMessage()]


def _fresh_peer_log(server) -> None:
    """Forget what earlier tests logged (a peer's kind of line is logged once per 10 s)."""
    server.server.bserver.peer_log = PeerLog(logging.getLogger("softplc.adapters.opcua.transport"))


async def _first_frame_type(reader: asyncio.StreamReader, timeout: float) -> bytes | None:
    """The type of the first frame the server sends within `timeout`, b"" if it closes, None if silent."""
    try:
        return (await _read_frame_within(reader, timeout))[0]
    except TimeoutError:
        return None
    except asyncio.IncompleteReadError:
        return b""


async def _read_frame_within(reader: asyncio.StreamReader, timeout: float) -> tuple[bytes, bytes]:
    return await asyncio.wait_for(_read_frame(reader), timeout)


async def test_one_peer_cannot_hold_every_connection_and_a_flood_logs_a_line(plant, caplog: pytest.LogCaptureFixture) -> None:
    runtime, server = plant
    caplog.set_level(logging.WARNING)
    limit = server.settings.max_connections_per_peer
    _fresh_peer_log(server)
    sockets = [await asyncio.open_connection("127.0.0.1", _port(server)) for _ in range(limit + 30)]
    try:
        # The connections beyond the limit are answered with an ERR message and closed at once.
        answers = await asyncio.gather(*(_first_frame_type(reader, 1.0) for reader, _ in sockets))
        assert answers.count(b"ERR") == 30 and answers.count(None) == limit
        assert len(server.server.bserver.clients) == limit
        await _scan_advances(runtime)
        assert len(_warnings(caplog, "refusing a connection from 127.0.0.1")) == 1
    finally:
        for _, writer in sockets:
            writer.close()
    await wait_until(lambda: len(server.server.bserver.clients) == 0, timeout=5)
    await _other_client_works(server)


async def test_idle_connections_are_closed_with_one_log_line(plant, caplog: pytest.LogCaptureFixture) -> None:
    _, server = plant
    caplog.set_level(logging.WARNING)
    _fresh_peer_log(server)
    iserver = server.server.iserver
    patience, iserver.max_pending_activation_seconds = iserver.max_pending_activation_seconds, 0.3
    sockets = []
    try:
        sockets = [await asyncio.open_connection("127.0.0.1", _port(server)) for _ in range(40)]
        # They never say Hello: each is closed after 0.3 s.
        assert await asyncio.gather(*(_first_frame_type(reader, 5) for reader, _ in sockets)) == [b""] * 40
    finally:
        iserver.max_pending_activation_seconds = patience
        for _, writer in sockets:
            writer.close()
    assert len(_warnings(caplog, "no session activated") + _warnings(caplog, "idle")) == 1
    await _other_client_works(server)
