"""The standard OPC UA nodes a server starts with: built by asyncua once, then loaded from the cache."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest
from asyncua import Server, ua

from softplc.adapters.opcua.standard_nodes import LazyNodes, cache_path, init_server
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


async def test_loaded_nodes_are_unpickled_only_when_asked_for(tmp_path: Path) -> None:
    path = tmp_path / "nodes.pickle"
    built = await _started(path)
    loaded = await _started(path)
    nodes = loaded.iserver.aspace._nodes
    assert isinstance(nodes, LazyNodes)
    still_pickled = len(nodes._pickled)
    assert still_pickled > 5000  # asyncua's init and the Server object touched a few hundred at most
    node_id = ua.NodeId(ua.ObjectIds.AnalogItemType)
    assert node_id in nodes and len(nodes._pickled) == still_pickled  # `in` unpickles nothing
    ours, theirs = loaded.iserver.aspace[node_id], built.iserver.aspace[node_id]
    assert len(nodes._pickled) == still_pickled - 1 and loaded.iserver.aspace.get(node_id) is ours
    assert ours.attributes[ua.AttributeIds.BrowseName].value.Value == theirs.attributes[ua.AttributeIds.BrowseName].value.Value
    assert [ref.NodeId for ref in ours.references] == [ref.NodeId for ref in theirs.references]
    # Whole-dictionary views see every node; deleting one works for a pickled node too.
    assert len(nodes) == len(list(nodes)) == len(nodes.keys()) == len(built.iserver.aspace._nodes)
    other = ua.NodeId(ua.ObjectIds.AuditEventType)
    del nodes[other]
    assert other not in nodes and nodes.get(other) is None and len(nodes) == len(built.iserver.aspace._nodes) - 1
    with pytest.raises(KeyError):
        nodes[other]
    # A client browsing the type tree gets what a built server answers.
    async def names(server: Server) -> list[str]:
        children = await server.get_node(ua.ObjectIds.BaseDataVariableType).get_children()
        return sorted([(await child.read_browse_name()).Name for child in children])

    children = await names(loaded)
    assert children == await names(built) and "DataItemType" in children and len(children) > 10


async def test_a_cache_of_the_earlier_whole_format_is_replaced(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    path = cache_path()
    earlier = path.with_name(path.name.replace("-lazy1-", "-"))
    assert earlier != path
    earlier.parent.mkdir(parents=True, mode=0o700)
    earlier.write_bytes(b"the nodes pickled whole")
    await _started(path)
    assert path.is_file() and not earlier.exists()
