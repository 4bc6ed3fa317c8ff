"""OPC UA's standard address space (~6,000 nodes) for a starting server, from a cache when there is one.

asyncua builds the standard nodes from generated code on every start: 0.8-1.2 s of Python in a
thread here, most of an OPC UA server's start and a third of a simulated ten minutes of the default
plant. The first start on a machine (per user, asyncua and Python version) builds them as asyncua
does and saves them to `$XDG_CACHE_HOME/softplc/` (default `~/.cache/softplc/`), each node pickled
on its own; later starts load that file (~10 ms) and unpickle a node only when something asks for it
(`LazyNodes`). A server and a simulation touch a few hundred of the 6,000 (the default plant: 160);
a client that browses the type trees unpickles what it browses, ~50 µs a node. Unpickling all of
them at once took ~0.35 s of every simulated run. A cache that cannot be read, is not the user's
own or is writable by others is ignored (and rebuilt), since unpickling runs what the file says; one
that cannot be written is simply not kept.

The price is memory for what gets unpickled: an unpickled node holds more than a built one (all of
them: ~140 MB where asyncua's build holds ~40 MB, measured with asyncua 2.1.0, Python 3.11). The
OPC UA server therefore uses the cache only under a simulated clock, where start-up is a good part of
a run that ends in seconds; a server on the real clock, up for months and browsed by anyone, builds them.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import os
import pickle
import sys
from collections.abc import Iterator, KeysView
from importlib.metadata import version
from pathlib import Path
from typing import Any

from asyncua import Server
from asyncua.server.address_space import AddressSpace, NodeManagementService
from asyncua.server.standard_address_space import standard_address_space

from softplc.util.cache import cache_dir, trusted, write_atomic

log = logging.getLogger(__name__)

_FORMAT = "lazy1"  # each node pickled on its own (a cache of an earlier format is simply not found)


def cache_path() -> Path:
    """Where this machine's user keeps the standard nodes of this asyncua and Python version."""
    python = f"py{sys.version_info.major}{sys.version_info.minor}"
    return cache_dir() / f"opcua-standard-nodes-{_FORMAT}-asyncua-{version('asyncua')}-{python}.pickle"


class LazyNodes(dict):  # type: ignore[type-arg]
    """asyncua's node dictionary, with the standard nodes kept pickled until first asked for.

    Reads by key (`[]`, `get`, `in`) unpickle the one node asked for; iterating, `len` and the
    key views see every node, pickled or not; `values()`/`items()` (asyncua uses them only to
    dump an address space) unpickle them all. A node found already unpickled by another thread
    is the one kept, so every holder sees the same object.
    """

    def __init__(self, pickled: dict[Any, bytes]) -> None:
        super().__init__()
        self._pickled = pickled

    def __missing__(self, key: Any) -> Any:
        blob = self._pickled.get(key)
        if blob is None:
            raise KeyError(key)
        node = self.setdefault(key, pickle.loads(blob))
        self._pickled.pop(key, None)
        return node

    def get(self, key: Any, default: Any = None) -> Any:
        try:
            return self[key]
        except KeyError:
            return default

    def __contains__(self, key: object) -> bool:
        return dict.__contains__(self, key) or key in self._pickled

    def __delitem__(self, key: Any) -> None:
        if self._pickled.pop(key, None) is None:
            dict.__delitem__(self, key)
        else:
            dict.pop(self, key, None)

    def pop(self, key: Any, *default: Any) -> Any:
        if key in self._pickled:
            self[key]  # unpickled, then popped like any other
        return dict.pop(self, key, *default)

    def __iter__(self) -> Iterator[Any]:
        yield from list(dict.keys(self))
        yield from [key for key in list(self._pickled) if not dict.__contains__(self, key)]

    def __len__(self) -> int:
        return dict.__len__(self) + sum(1 for key in list(self._pickled) if not dict.__contains__(self, key))

    def keys(self) -> KeysView[Any]:  # type: ignore[override]
        return KeysView(self)

    def values(self) -> Any:
        self._unpickle_all()
        return dict.values(self)

    def items(self) -> Any:
        self._unpickle_all()
        return dict.items(self)

    def clear(self) -> None:
        self._pickled.clear()
        dict.clear(self)

    def copy(self) -> dict[Any, Any]:
        self._unpickle_all()
        return dict(dict.items(self))

    def __reduce__(self) -> Any:
        return (dict, (self.copy(),))

    def _unpickle_all(self) -> None:
        for key in list(self._pickled):
            self.get(key)


async def init_server(server: Server, path: Path | None = None) -> None:
    """`server.init()`, with the standard nodes taken from (or saved to) the cache at `path`."""
    path = path or cache_path()
    iserver = server.iserver

    async def load_standard_address_space(shelf_file: Path | None = None) -> None:
        # Replaces asyncua's own loader for this one server; asyncua's init does the rest (its
        # fixes to the standard nodes, the Server object, namespaces) as after its own loader.
        await asyncio.to_thread(_fill, iserver.aspace, path)

    iserver.load_standard_address_space = load_standard_address_space  # type: ignore[method-assign]
    await server.init()


def _fill(aspace: AddressSpace, path: Path) -> None:
    pickled = _load(path)
    if pickled is None:
        standard_address_space.fill_address_space(NodeManagementService(aspace))
        # Pickled before asyncua's init changes them: what is saved is the standard nodes as built.
        pickled = {node_id: pickle.dumps(node, pickle.HIGHEST_PROTOCOL) for node_id, node in aspace._nodes.items()}
        _save(pickled, path)
    nodes = LazyNodes(pickled)
    dict.update(nodes, aspace._nodes)  # what asyncua made before (nothing today) stays as it is
    for node_id in aspace._nodes:
        pickled.pop(node_id, None)
    aspace._nodes = nodes  # asyncua keeps the nodes in this dict, no public way to hand them over


def _load(path: Path) -> dict[Any, bytes] | None:
    try:
        with path.open("rb") as file:
            if not trusted(os.fstat(file.fileno())) or not trusted(path.parent.stat()):
                log.warning("ignoring %s: not owned by this user, or writable by others", path)
                return None
            collecting = gc.isenabled()
            gc.disable()  # ~12,000 objects: no collector's passes meanwhile
            try:
                pickled = pickle.load(file)
            finally:
                if collecting:
                    gc.enable()
    except FileNotFoundError:
        return None
    except Exception as error:  # noqa: BLE001 — a torn or stale file: build the nodes as asyncua does
        log.warning("ignoring the OPC UA standard nodes cache %s (%s); building them anew", path, error)
        return None
    if not isinstance(pickled, dict) or not all(isinstance(blob, bytes) for blob in pickled.values()):
        log.warning("ignoring the OPC UA standard nodes cache %s (not a cache of this version); building them anew", path)
        return None
    return pickled


def _save(pickled: dict[Any, bytes], path: Path) -> None:
    try:
        write_atomic(path, lambda file: pickle.dump(pickled, file, protocol=pickle.HIGHEST_PROTOCOL))
    except Exception as error:  # noqa: BLE001 — no cache then; the next start builds the nodes again
        log.info("could not keep the OPC UA standard nodes in %s: %s", path, error)
        return
    if f"-{_FORMAT}-" in path.name:  # the same nodes pickled whole, as softplc kept them before: never read again
        try:
            path.with_name(path.name.replace(f"-{_FORMAT}-", "-")).unlink(missing_ok=True)
        except OSError:
            pass
