"""The standby's end of the sync link: connect to the active, check it, apply its states in order.

Each state is checked by the core (`plant.replication.apply`, which refuses anything malformed or
out of order without applying it) and acknowledged; journal entries are held until a state says
the active applied them. Anything refused is reported, the connection is closed, and the next
connection starts again from a full state.
"""

from __future__ import annotations

import asyncio
import logging
import os
import ssl
from typing import Any

from softplc.adapters.redundancy.link import VERSION, LinkRefused, check_data, check_welcome, encode, read_message
from softplc.adapters.redundancy.sync_server import HANDSHAKE_TIMEOUT
from softplc.core.plant import StateRefused
from softplc.security.pair_certificates import fingerprint_of_der
from softplc.util.tasks import within

log = logging.getLogger(__name__)

SILENCE = 3.0  # s without a frame from the active before the link counts as broken


class SyncClient:
    """One connection to the active (see the module docstring); `run()` returns when it ends."""

    def __init__(self, adapter: Any, context: ssl.SSLContext, peer_fingerprint: str, address: tuple[str, int], active: str) -> None:
        self.adapter = adapter  # softplc.adapters.redundancy.adapter.RedundancyAdapter
        self.context = context
        self.peer_fingerprint = peer_fingerprint
        self.address = address
        self.active = active
        self.applied_at: float | None = None
        self.full = False  # a full state has been applied on this connection

    async def run(self) -> None:
        """Connect, sync until the link ends; raises LinkRefused (reported by the caller) or a connection error."""
        adapter = self.adapter
        plant = adapter.plant
        host, port = self.address
        try:
            reader, writer = await within(HANDSHAKE_TIMEOUT + 1, asyncio.open_connection(
                host, port, ssl=self.context, server_hostname=f"softplc-{self.active}", ssl_handshake_timeout=HANDSHAKE_TIMEOUT))
        except ssl.SSLError as error:
            raise LinkRefused(f"TLS handshake with {host}:{port} failed ({error.reason or error}): not the pinned peer") from None
        try:
            der = writer.get_extra_info("ssl_object").getpeercert(binary_form=True)
            if der is None or fingerprint_of_der(der) != self.peer_fingerprint:
                raise LinkRefused(f"{host}:{port} presents a certificate that is not the peer's pinned one")
            nonce = os.urandom(16)
            writer.write(encode(["hello", VERSION, adapter.settings.me.name, adapter.config_hash, nonce, plant.role.epoch]))
            member, config_hash, epoch = check_welcome(await within(HANDSHAKE_TIMEOUT, read_message(reader)), nonce)
            if member != adapter.settings.peer.name:
                raise LinkRefused(f"{host}:{port} says it is {member!r}, the peer is {adapter.settings.peer.name!r}")
            if config_hash != adapter.config_hash:
                raise LinkRefused(f"the active runs another configuration (hash {config_hash[:12]} there, {adapter.config_hash[:12]} here)")
            if epoch < plant.role.epoch:
                raise LinkRefused(f"{member} offers epoch {epoch}, older than {plant.role.epoch} known here")
            adapter.following(epoch, member)
            counter = 0
            replication = plant.replication
            while True:
                # The active sends a state every cycle, or a heartbeat every 0.2 s: silence means a
                # half-open link (a frozen active, a cut cable) — reconnect rather than wait for ever.
                message = await within(SILENCE, read_message(reader))
                counter += 1
                payload = check_data(message, epoch, counter)
                if not isinstance(payload, list) or not payload:
                    raise LinkRefused("a data frame without a state or journal message")
                try:
                    if payload[0] == "state":
                        if not self.full and not (len(payload) > 2 and payload[2] is True):
                            raise LinkRefused("a partial state before the full one")
                        replication.apply(payload)
                        self.full = True
                        self.applied_at = plant.clock.now()
                        adapter.synced(self)
                        writer.write(encode(["ack", payload[1]]))
                    elif payload[0] == "journal":
                        replication.hold(payload)
                    else:
                        raise LinkRefused(f"a data frame of kind {str(payload[0])[:40]!r}")
                except StateRefused as refused:
                    raise LinkRefused(f"state refused: {refused}") from None
        except LinkRefused as refused:
            try:
                writer.write(encode(["refuse", str(refused)]))
                await within(1.0, writer.drain())
            except Exception:  # the link is gone already
                pass
            raise
        finally:
            writer.close()
