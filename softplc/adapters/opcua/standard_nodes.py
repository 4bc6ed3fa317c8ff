"""OPC UA's standard address space (~6,000 nodes) for a starting server, from a cache when there is one.

asyncua builds the standard nodes from generated code on every start: 0.8-1.2 s of Python in a
thread here, most of an OPC UA server's start and a third of a simulated ten minutes of the default
plant. The same nodes unpickled take a third of that. The first start on a machine (per user,
asyncua and Python version) builds them as asyncua does and saves them to
`$XDG_CACHE_HOME/softplc/` (default `~/.cache/softplc/`); later starts load that file. A cache that
cannot be read, is not the user's own or is writable by others is ignored (and rebuilt), since
unpickling runs what the file says; one that cannot be written is simply not kept.

The price is memory: unpickled, the nodes hold ~140 MB of the process's memory where asyncua's
build holds ~40 MB (measured with asyncua 2.1.0, Python 3.11). The OPC UA server therefore uses the
cache only under a simulated clock, where start-up is a good part of a run that ends in seconds.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import os
import pickle
import sys
from importlib.metadata import version
from pathlib import Path
from typing import Any

from asyncua import Server
from asyncua.server.address_space import AddressSpace, NodeManagementService
from asyncua.server.standard_address_space import standard_address_space

from softplc.util.cache import cache_dir, trusted, write_atomic

log = logging.getLogger(__name__)


def cache_path() -> Path:
    """Where this machine's user keeps the standard nodes of this asyncua and Python version."""
    python = f"py{sys.version_info.major}{sys.version_info.minor}"
    return cache_dir() / f"opcua-standard-nodes-asyncua-{version('asyncua')}-{python}.pickle"


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
    nodes = _load(path)
    if nodes is not None:
        aspace._nodes.update(nodes)  # asyncua keeps the nodes in this dict, no public way to hand them over
        return
    standard_address_space.fill_address_space(NodeManagementService(aspace))
    _save(dict(aspace._nodes), path)


def _load(path: Path) -> dict[Any, Any] | None:
    try:
        with path.open("rb") as file:
            if not trusted(os.fstat(file.fileno())) or not trusted(path.parent.stat()):
                log.warning("ignoring %s: not owned by this user, or writable by others", path)
                return None
            collecting = gc.isenabled()
            gc.disable()  # ~100,000 objects: the collector's passes meanwhile would triple the time
            try:
                nodes = pickle.load(file)
            finally:
                if collecting:
                    gc.enable()
    except FileNotFoundError:
        return None
    except Exception as error:  # noqa: BLE001 — a torn or stale file: build the nodes as asyncua does
        log.warning("ignoring the OPC UA standard nodes cache %s (%s); building them anew", path, error)
        return None
    return nodes if isinstance(nodes, dict) else None


def _save(nodes: dict[Any, Any], path: Path) -> None:
    try:
        write_atomic(path, lambda file: pickle.dump(nodes, file, protocol=pickle.HIGHEST_PROTOCOL))
    except Exception as error:  # noqa: BLE001 — no cache then; the next start builds the nodes again
        log.info("could not keep the OPC UA standard nodes in %s: %s", path, error)

