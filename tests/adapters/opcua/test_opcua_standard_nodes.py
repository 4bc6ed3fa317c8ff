"""The standard OPC UA nodes a server starts with: built by asyncua once, then loaded from the cache."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest
from asyncua import Server, ua

from softplc.adapters.opcua.standard_nodes import init_server
from softplc.core.clock import RealClock, SimClock
from tests.opcua_support import running_plant

pytestmark = pytest.mark.asyncio


async def _started(path: Path) -> Server:
    server = Server()
    await init_server(server, path)
    return server


async def _described(server: Server) -> tuple[int, str, list[str]]:
    """How many nodes, the Server object's browse name, and the names under it."""
    node = server.get_node(ua.ObjectIds.Server)
    children = sorted(child.Name for child in [await c.read_browse_name() for c in await node.get_children()])
    return len(server.iserver.aspace._nodes), (await node.read_browse_name()).Name, children


async def test_a_second_start_loads_the_nodes_the_first_built(tmp_path: Path) -> None:
    path = tmp_path / "cache" / "nodes.pickle"
    built = await _started(path)
    assert path.is_file()
    assert oct(path.stat().st_mode & 0o777) == oct(0o600) and oct(path.parent.stat().st_mode & 0o777) == oct(0o700)
    loaded = await _started(path)
    first, second = await _described(built), await _described(loaded)
    assert first == second and first[0] > 5000 and "ServerStatus" in first[2]
    assert set(built.iserver.aspace._nodes) == set(loaded.iserver.aspace._nodes)


async def test_a_torn_cache_is_ignored_and_made_again(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "nodes.pickle"
    await _started(path)
    whole = path.read_bytes()
    path.write_bytes(whole[: len(whole) // 2])
    with caplog.at_level(logging.WARNING):
        server = await _started(path)
    assert "ignoring the OPC UA standard nodes cache" in caplog.text
    assert (await _described(server))[0] > 5000
    assert path.read_bytes() == whole  # made again, whole


async def test_a_cache_others_may_write_is_not_loaded(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "nodes.pickle"
    path.write_bytes(b"not a pickle anyone should run")
    os.chmod(path, 0o666)
    with caplog.at_level(logging.WARNING):
        server = await _started(path)
    assert "not owned by this user, or writable by others" in caplog.text
    assert (await _described(server))[0] > 5000
    assert path.stat().st_mode & 0o777 == 0o600  # replaced by the server's own


async def test_a_cache_that_cannot_be_written_only_costs_the_build(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache directory would be")
    server = await _started(blocker / "nodes.pickle")
    assert (await _described(server))[0] > 5000


@pytest.mark.parametrize("clock", [RealClock, SimClock])
async def test_only_a_simulation_keeps_and_loads_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, clock: type) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    async with running_plant(tmp_path, security=("None",), clock=clock()):
        pass
    kept = list((tmp_path / "cache").glob("softplc/*.pickle"))
    assert len(kept) == (1 if clock is SimClock else 0)
