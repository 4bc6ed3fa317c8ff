"""The sync link is a door into the plant: only the pinned peer of the same configuration gets in,
and a malformed, replayed or out-of-place message is refused, reported and never applied."""

from __future__ import annotations

import asyncio
import json
import os
import ssl
from pathlib import Path
from typing import Any

import pytest

from softplc.adapters.redundancy.link import VERSION, encode, read_message
from softplc.app.runtime import Runtime
from softplc.security.pair_certificates import link_context, make_pair
from tests.adapters.redundancy.pair_support import write_pair
from tests.adapters.redundancy.test_pair_inprocess import member, role, until


async def tls_connect(port: int, certificate: Path, key: Path, peer: Path) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    await writer.start_tls(link_context(certificate, key, peer, server=False), server_hostname="softplc-a")
    return reader, writer


def sync_port(runtime: Runtime) -> int:
    adapter = next(adapter for adapter in runtime.adapters if adapter.name == "redundancy")
    return adapter.server.port


@pytest.fixture
async def active(tmp_path: Path, etcd: Any) -> Any:
    path = write_pair(tmp_path, etcd.endpoint)
    a = member(path, "a", tmp_path)
    await a.start()
    await until(lambda: role(a) == "ACTIVE", 10, "a active")
    yield a, tmp_path
    await a.stop()


async def refused_count(runtime: Runtime, before: int) -> None:
    await until(lambda: runtime.db.value("_sys.redundancy.refused") > before, 5, "the refusal is counted")


async def test_a_stranger_without_the_pinned_certificate_never_gets_past_tls(active: Any) -> None:
    a, folder = active
    make_pair(folder / "stranger", "b", "other")  # a member "b" of another pair: its own certificate
    with pytest.raises((ssl.SSLError, ConnectionError, asyncio.IncompleteReadError)):
        reader, writer = await tls_connect(sync_port(a), folder / "stranger" / "b.crt", folder / "stranger" / "b.key", folder / "pair" / "a.crt")
        writer.write(encode(["hello", VERSION, "b", "x", os.urandom(16), 0]))
        await read_message(reader)
    await refused_count(a, 0)
    assert "TLS handshake failed" in a.db.value("_sys.redundancy.peer")


async def test_the_pinned_peer_with_another_configuration_is_refused_and_told_why(active: Any) -> None:
    a, folder = active
    reader, writer = await tls_connect(sync_port(a), folder / "pair" / "b.crt", folder / "pair" / "b.key", folder / "pair" / "a.crt")
    writer.write(encode(["hello", VERSION, "b", "0" * 64, os.urandom(16), 0]))
    answer = await asyncio.wait_for(read_message(reader), 5)
    assert answer[0] == "refuse" and "another configuration" in answer[1]
    await refused_count(a, 0)
    writer.close()


async def test_a_malformed_hello_is_refused(active: Any) -> None:
    a, folder = active
    reader, writer = await tls_connect(sync_port(a), folder / "pair" / "b.crt", folder / "pair" / "b.key", folder / "pair" / "a.crt")
    writer.write(b"\x00\x00\x00\x05hello")  # a frame, but not MessagePack
    answer = await asyncio.wait_for(read_message(reader), 5)
    assert answer[0] == "refuse" and "not MessagePack" in answer[1]
    await refused_count(a, 0)


class FakeActive:
    """Member a as a bad (or compromised) active: it holds the etcd key and feeds the standby what the test says."""

    def __init__(self, folder: Path, port: int) -> None:
        self.context = link_context(folder / "pair" / "a.crt", folder / "pair" / "a.key", folder / "pair" / "b.crt", server=True)
        self.port = port
        self.frames: list[Any] = []
        self.answers: list[Any] = []
        self.server: asyncio.AbstractServer | None = None

    async def start(self) -> None:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", self.port, ssl=self.context)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            hello = await read_message(reader)
            writer.write(encode(["welcome", VERSION, "a", hello[3], hello[4], 1_000_000]))
            for frame in self.frames:
                writer.write(encode(frame))
            while True:
                self.answers.append(await read_message(reader))
        except Exception:
            pass
        finally:
            writer.close()

    async def stop(self) -> None:
        if self.server is not None:
            self.server.close()


async def hold_key(etcd: Any, key: str, value: dict[str, Any]) -> Any:
    import aetcd

    host, port = etcd.endpoint.split(":")
    client = aetcd.Client(host, int(port), timeout=2)
    lease = await client.lease(30)
    await client.put(key.encode(), json.dumps(value).encode(), lease=lease)
    return client


async def test_a_malformed_or_replayed_state_from_the_active_is_refused_and_nothing_is_applied(tmp_path: Path, etcd: Any) -> None:
    path = write_pair(tmp_path, etcd.endpoint)
    client = await hold_key(etcd, "/softplc/pairtest/active", {"member": "a"})
    b = member(path, "b", tmp_path)
    port = int(path.read_text().split('a: {sync: "127.0.0.1:')[1].split('"')[0])
    fake = FakeActive(tmp_path, port)
    good = b.replication.capture_full()  # a well-formed full state (this plant's own)
    good[6] = [["scans", 99, "good", 0.0]]
    evil = [*good[:6], [["scans", 5, "good", 0.0]], *good[7:]]
    evil[1] = good[1] + 1
    evil[2] = False
    fake.frames = [
        ["data", 1_000_000, 1, good],
        ["data", 1_000_000, 1, evil],  # the same counter again: a replayed frame
    ]
    await fake.start()
    await b.start()
    try:
        await until(lambda: b.db.value("_sys.redundancy.refused") >= 1, 10, "the replayed frame is refused")
        assert b.db.value("scans") == 99  # the good state was applied, the replayed one not
        assert "replayed" in b.db.value("_sys.redundancy.peer")
        # the refusal is sent before the link closes; the active reads it in its own time
        await until(lambda: any(answer[0] == "refuse" and "replayed" in answer[1] for answer in fake.answers), 5,
                    "the refusal reaches the active")
        before = b.db.value("_sys.redundancy.refused")
        fake.frames = [["data", 1_000_000, 1, [*good[:6], [["no_such_tag", 1, "good", 0.0]], *good[7:]]]]
        await until(lambda: b.db.value("_sys.redundancy.refused") > before, 5, "the malformed state is refused")
        assert "no replicated tag 'no_such_tag'" in b.db.value("_sys.redundancy.peer") and b.db.value("scans") == 99
        assert role(b) == "STANDBY"  # it never took over: the key is held
    finally:
        await b.stop()
        await fake.stop()
        await client.close()
