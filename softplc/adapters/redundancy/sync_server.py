"""The active's end of the sync link: it accepts its standby, sends it the whole state, then every cycle's.

Every member listens; only the active welcomes. A connection is refused — and reported, nothing
of it applied — when its TLS handshake fails (a stranger: no certificate, or not the pinned one),
when its hello names another member or a different configuration, or when this member is not
active. A standby too slow to keep up (its unread backlog past BACKLOG bytes) is dropped and
resynchronises from a full state when it reconnects.

The active's costs sit on its scan path: at each cycle boundary `send_cycle` captures what
changed and writes one frame to the socket; writes journaled are forwarded as they are
acknowledged. Both are a few tens of microseconds for a small plant (bench/redundancy_failover.py).
"""

from __future__ import annotations

import asyncio
import logging
import ssl
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from softplc.adapters.redundancy.link import VERSION, LinkRefused, check_hello, encode, expect, read_message
from softplc.security.pair_certificates import fingerprint_of_der
from softplc.util.tasks import within

if TYPE_CHECKING:
    from softplc.core.plant import Plant, TaskView

log = logging.getLogger(__name__)

HANDSHAKE_TIMEOUT = 5.0
BACKLOG = 64 * 1024 * 1024


class StandbyConnection:
    """The standby connected to this active: its stream, the frames counted, the acknowledgements."""

    def __init__(self, writer: asyncio.StreamWriter, epoch: int, now: float) -> None:
        self.writer = writer
        self.epoch = epoch
        self.counter = 0
        self.sent_sequence = 0
        self.acked_sequence = 0
        self.acked_at = now
        self.closed = False

    def send(self, payload: Any) -> bool:
        """Write one data frame; False (and closed) when the standby cannot keep up or is gone."""
        if self.closed:
            return False
        transport = self.writer.transport
        if transport.is_closing() or transport.get_write_buffer_size() > BACKLOG:
            self.close()
            return False
        self.counter += 1
        self.writer.write(encode(["data", self.epoch, self.counter, payload]))
        return True

    def close(self) -> None:
        self.closed = True
        self.writer.close()


class SyncServer:
    """Listens for the standby; while this member is active, feeds it (see the module docstring)."""

    def __init__(self, adapter: Any, context: ssl.SSLContext, peer_fingerprint: str) -> None:
        self.adapter = adapter  # softplc.adapters.redundancy.adapter.RedundancyAdapter
        self.context = context
        self.peer_fingerprint = peer_fingerprint
        self.standby: StandbyConnection | None = None
        self._server: asyncio.AbstractServer | None = None
        self._handlers: set[asyncio.Task[Any]] = set()
        self.port = 0

    async def start(self, host: str, port: int) -> None:
        loop = asyncio.get_running_loop()
        self._server = await loop.create_server(lambda: _Unread(self._upgrade), host, port, reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]

    def _upgrade(self, transport: asyncio.Transport) -> None:
        """A new connection, not read from yet: TLS first (every byte the peer sent goes to the handshake)."""
        task = asyncio.ensure_future(self._accept_tls(transport))
        self._handlers.add(task)
        task.add_done_callback(self._handlers.discard)

    async def stop(self) -> None:
        self.drop("this runtime stops")
        if self._server is not None:
            self._server.close()
        for task in list(self._handlers):
            task.cancel()
        if self._handlers:
            await asyncio.gather(*self._handlers, return_exceptions=True)

    def drop(self, why: str) -> None:
        """Close the standby's connection (a lost role, a stop)."""
        if self.standby is not None:
            log.info("redundancy: closing the link to the standby: %s", why)
            self.standby.close()
            self.standby = None

    # -- feeding ---------------------------------------------------------------------------

    def send_cycle(self, plant: Plant, task: TaskView) -> None:
        """At a cycle boundary: capture what changed, encode and send it (nothing when no standby listens) — just after it.

        Nothing of it runs inside the task's cycle: the capture is the loop's next callback. That is
        still this cycle's state: the engine starts its next cycle only after `await sleep(0)`,
        whose wake-up is queued behind this callback, and programs, forces and journaled writes
        change only in a cycle. (A `_sys.`-free tag an adapter commits in between goes with it,
        one state early; the standby takes it either way.)
        """
        if self.standby is not None:
            asyncio.get_running_loop().call_soon(self._capture_and_send, plant, task)

    def _capture_and_send(self, plant: Plant, task: TaskView) -> None:
        standby = self.standby
        if standby is None:
            return
        state = plant.replication.capture(task)
        standby.sent_sequence = state[1]
        if not standby.send(state):
            self._lost(standby, "it could not keep up (its backlog passed the limit) or went away")

    def send_journal(self, message: list[Any]) -> None:
        """Send journaled writes at once, before the writer is answered (a state captured earlier may follow them)."""
        standby = self.standby
        if standby is not None and not standby.send(message):
            self._lost(standby, "it could not keep up or went away")

    def _lost(self, standby: StandbyConnection, why: str) -> None:
        if self.standby is standby:
            self.standby = None
            self.adapter.peer_changed(f"gone: {why}")

    # -- accepting -------------------------------------------------------------------------

    async def _accept_tls(self, transport: asyncio.Transport) -> None:
        peer = transport.get_extra_info("peername")
        where = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        loop = asyncio.get_running_loop()
        reader = asyncio.StreamReader()
        protocol = asyncio.StreamReaderProtocol(reader)
        try:
            secured = await within(HANDSHAKE_TIMEOUT, loop.start_tls(transport, protocol, self.context, server_side=True))
        except (ssl.SSLError, asyncio.TimeoutError, ConnectionError, OSError) as error:
            transport.close()
            self.adapter.refused(f"sync link from {where}: TLS handshake failed ({_reason(error)}): not the pinned peer")
            return
        if secured is None:
            transport.close()
            return
        protocol.connection_made(secured)
        writer = asyncio.StreamWriter(secured, protocol, reader, loop)
        await self._accept(reader, writer, where)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, where: str) -> None:
        try:
            await self._serve(reader, writer, where)
        except LinkRefused as refused:
            self.adapter.refused(f"sync link from {where}: {refused}")
            await _say_refused(writer, str(refused))
        except (asyncio.IncompleteReadError, ConnectionError, OSError, asyncio.TimeoutError, ssl.SSLError) as error:
            if self.standby is not None and self.standby.writer is writer:
                self._lost(self.standby, f"the link broke ({type(error).__name__})")
        finally:
            if self.standby is not None and self.standby.writer is writer:
                self._lost(self.standby, "the link closed")
            writer.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, where: str) -> None:
        adapter = self.adapter
        der = writer.get_extra_info("ssl_object").getpeercert(binary_form=True)
        if der is None or fingerprint_of_der(der) != self.peer_fingerprint:
            raise LinkRefused("its certificate is not the peer's pinned certificate")
        member, config_hash, nonce, _ = check_hello(await within(HANDSHAKE_TIMEOUT, read_message(reader)))
        if member != adapter.settings.peer.name:
            raise LinkRefused(f"it says it is {member!r}, the peer is {adapter.settings.peer.name!r}")
        if config_hash != adapter.config_hash:
            raise LinkRefused(f"it runs another configuration (hash {config_hash[:12]} there, {adapter.config_hash[:12]} here): "
                              "the two runtimes' plant files or programs differ")
        plant = adapter.plant
        if not plant.role.is_active():
            raise LinkRefused(f"{adapter.settings.me.name} is not active (the active is {adapter.active_name or 'unknown'})")
        epoch = plant.role.epoch
        writer.write(encode(["welcome", VERSION, adapter.settings.me.name, adapter.config_hash, nonce, epoch]))
        if self.standby is not None:
            self.standby.close()
        standby = StandbyConnection(writer, epoch, plant.clock.now())
        # The whole state and the writes not yet applied, in one step of the loop: nothing in between.
        full = plant.replication.capture_full()
        standby.sent_sequence = full[1]
        standby.send(full)
        standby.send(plant.replication.pending_journal())
        self.standby = standby
        log.info("redundancy: standby %s connected from %s; full state %d sent", member, where, full[1])
        adapter.peer_changed("syncing")
        while True:
            message = await read_message(reader)
            _, sequence = expect(message, "ack", 2)
            if not isinstance(sequence, int) or sequence > standby.sent_sequence:
                raise LinkRefused(f"an acknowledgement of state {sequence!r}, never sent")
            standby.acked_sequence = sequence
            standby.acked_at = plant.clock.now()


async def _say_refused(writer: asyncio.StreamWriter, why: str) -> None:
    try:
        if writer.get_extra_info("ssl_object") is not None and not writer.transport.is_closing():
            writer.write(encode(["refuse", why]))
            await within(1.0, writer.drain())
    except Exception:  # the peer is gone or never spoke TLS: nothing to tell it
        pass


def _reason(error: BaseException) -> str:
    if isinstance(error, asyncio.TimeoutError):
        return "timed out"
    return getattr(error, "reason", None) or type(error).__name__


class _Unread(asyncio.Protocol):
    """A connection's first protocol: it reads nothing, so the TLS handshake that follows gets every byte."""

    def __init__(self, upgrade: Callable[[asyncio.Transport], None]) -> None:
        self.upgrade = upgrade

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        transport.pause_reading()
        self.upgrade(transport)
