"""A link to a Modbus TCP server: bound registers polled every period in grouped requests, writes in runs.

pymodbus's `AsyncModbusTcpClient` speaks the protocol (no retries, no reconnects of its own: the
link reconnects with backoff on the plant clock). What the remote answers is judged per group:

- an exception code (02 illegal address, 04 device failure...) makes the group's tags BAD with
  that reason; a group answered 02 or 03 is then read binding by binding, so one wrong address
  does not hide its neighbours;
- fewer registers than asked, or bytes that are no Modbus frame ("garbage"), make the link drop
  the connection and reconnect (the tags are BAD meanwhile, with the reason);
- a register block that is no value of the tag's encoding (a string that is not UTF-8), or a
  value outside the tag's type or range, makes that tag BAD, keeping its last good value.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence
from typing import Any

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from softplc.adapters.links.link import Link, LinkError
from softplc.adapters.links.modbus_groups import ReadGroup, read_groups, write_runs
from softplc.adapters.links.quality import BoundTag
from softplc.adapters.links.settings import Binding, LinkSettings
from softplc.core.plant import Plant
from softplc.core.tags import Quality
from softplc.protocols.modbus_codec import CodecError

log = logging.getLogger(__name__)

EXCEPTIONS = {
    1: "illegal function", 2: "illegal data address", 3: "illegal data value", 4: "server device failure",
    5: "acknowledge", 6: "server device busy", 8: "memory parity error", 10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}
_SPLIT_ON = (2, 3)  # exceptions that may concern one binding of a group: read them one by one


def exception_text(code: int) -> str:
    return f"exception {code:02d} ({EXCEPTIONS.get(code, 'unknown')})"


class ModbusLink(Link):
    """Polls a Modbus TCP server (see the module docstring)."""

    def __init__(self, settings: LinkSettings, plant: Plant) -> None:
        super().__init__(settings, plant)
        readers = [bound.binding for bound in self.readers]
        self.groups = read_groups(readers, max_registers=settings.max_registers, max_bits=settings.max_bits, gap=settings.gap)
        self._base_groups = list(self.groups)
        self.client: AsyncModbusTcpClient | None = None
        self._lost = asyncio.Event()
        self._unframed = 0  # bytes received since the last whole answer: garbage when a request then fails
        self.polls = 0

    # -- connection ---------------------------------------------------------------------

    async def connect(self) -> None:
        settings = self.settings
        self._lost = asyncio.Event()
        self._unframed = 0
        self.groups = list(self._base_groups)
        self.client = AsyncModbusTcpClient(
            settings.host, port=settings.port, timeout=settings.timeout, retries=0, reconnect_delay=0,
            trace_packet=self._packet, trace_pdu=self._pdu, trace_connect=self._connection,
        )
        if not await self.client.connect():
            raise LinkError(f"cannot connect to {settings.host}:{settings.port} (refused, or no answer within {settings.timeout:g} s)")
        await self.poll()  # the first answer tells whether the remote serves the bound registers
        if len(self.groups) != len(self._base_groups):
            await self.poll()  # a group answered with an exception: its bindings one by one tell which

    def binding_problems(self) -> list[tuple[Binding, str]]:
        """Registers the remote does not serve (exception 01 or 02 for a binding read alone)."""
        return [(bound.binding, bound.reason) for bound in self.readers if bound.quality is Quality.BAD
                and ("illegal data address" in bound.reason or "illegal function" in bound.reason)
                and sum(len(g.bindings) for g in self.groups if bound.binding in g.bindings) == 1]

    async def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None

    def _packet(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            self._unframed += len(data)
        return data

    def _pdu(self, sending: bool, pdu: Any) -> Any:
        if not sending:
            self._unframed = 0
        return pdu

    def _connection(self, connected: bool) -> None:
        if not connected:
            self._lost.set()

    # -- reading ------------------------------------------------------------------------

    async def exchange(self) -> None:
        period = self.settings.period
        due = self.clock.now() + period
        while True:
            await self.clock.sleep_until(due)
            await self.poll()
            # An overrun (a slow remote) delays the next poll; it never fires a burst of catch-up polls.
            due = max(due + period, self.clock.now())

    async def poll(self) -> None:
        """Read every group once; journal what changed; raise LinkError when the connection fails."""
        started = self.clock.now()
        changed: list[BoundTag] = []
        for group in list(self.groups):
            words, code = await self._read(group)
            if code is not None:
                if code in _SPLIT_ON and len(group.bindings) > 1:
                    self._split(group)
                reason = f"{exception_text(code)} reading {group.describe()}"
                for binding in group.bindings:
                    bound = self.bound[binding.tag.name]
                    if bound.quality is not Quality.BAD or bound.reason != reason:
                        bound.bad(reason)
                        changed.append(bound)
                continue
            for binding in group.bindings:
                bound = self.bound[binding.tag.name]
                if self._decode(bound, words[binding.address - group.start:binding.address - group.start + binding.size]):
                    changed.append(bound)
        self.polls += 1
        self.answered(self.clock.now() - started)
        if changed or self.polls == 1:
            self.received(changed)

    def _decode(self, bound: BoundTag, words: list[int]) -> bool:
        """Take a binding's words; True when its value or verdict changed."""
        binding = bound.binding
        before = (bound.value, bound.quality, bound.reason)
        if binding.codec is None:
            bound.good(bool(words[0]))
        else:
            try:
                bound.good(binding.codec.decode(words))
            except CodecError as error:
                bound.bad(f"{binding.source}: {error}")
        return (bound.value, bound.quality, bound.reason) != before or type(bound.value) is not type(before[0])

    def _split(self, group: ReadGroup) -> None:
        """Read this group's bindings one by one from now on (until the next connection)."""
        index = self.groups.index(group)
        singles = [ReadGroup(group.table, b.address, b.size, (b,)) for b in group.bindings]
        self.groups[index:index + 1] = singles
        log.info("link %s: %s answered with an exception: reading its %d tags one by one to find which", self.name,
                 group.describe(), len(singles))

    async def _read(self, group: ReadGroup) -> tuple[list[int], int | None]:
        """The group's words (bits as 0/1), or the exception code the remote answered."""
        client = self._client()
        unit = self.settings.unit
        if group.table == "coil":
            request = client.read_coils(group.start, count=group.count, device_id=unit)
        elif group.table == "discrete_input":
            request = client.read_discrete_inputs(group.start, count=group.count, device_id=unit)
        elif group.table == "holding":
            request = client.read_holding_registers(group.start, count=group.count, device_id=unit)
        else:
            request = client.read_input_registers(group.start, count=group.count, device_id=unit)
        response = await self._request(request, f"reading {group.describe()}")
        if response.isError():
            return [], int(response.exception_code)
        if group.table in ("coil", "discrete_input"):
            bits = list(response.bits or [])
            if len(bits) < group.count:
                raise LinkError(f"the remote answered {len(bits)} bits for the {group.count} of {group.describe()}: garbage")
            return [int(bool(bit)) for bit in bits[:group.count]], None
        registers = list(response.registers or [])
        if len(registers) != group.count:
            raise LinkError(f"the remote answered {len(registers)} registers for the {group.count} of {group.describe()}: garbage")
        return registers, None

    async def _request(self, request: Any, what: str) -> Any:
        """One request, raced against the connection's loss; LinkError says what went wrong."""
        self.requests += 1
        task = asyncio.ensure_future(request)
        lost = asyncio.ensure_future(self._lost.wait())
        try:
            await asyncio.wait({task, lost}, return_when=asyncio.FIRST_COMPLETED)
        except asyncio.CancelledError:  # the plant stops: the request goes with it
            task.cancel()
            raise
        finally:
            lost.cancel()
        if not task.done():
            task.cancel()
            raise LinkError(self._failure(what, "the connection was closed"))
        try:
            return task.result()
        except ModbusException as error:
            raise LinkError(self._failure(what, _short(error))) from None

    def _failure(self, what: str, why: str) -> str:
        if self._unframed:
            return f"the remote answered garbage {what} ({self._unframed} bytes that are no Modbus answer); {why}"
        return f"{why} ({what})"

    def _client(self) -> AsyncModbusTcpClient:
        if self.client is None:
            raise LinkError("not connected")
        if self._lost.is_set():
            raise LinkError("the connection was closed (by the remote, or the network)")
        return self.client

    # -- writing ------------------------------------------------------------------------

    async def write(self, items: Sequence[tuple[BoundTag, Any]]) -> list[str | None]:
        answers: list[str | None] = [None] * len(items)
        batch: list[tuple[Binding, list[Any]]] = []
        for bound, value in items:
            binding = bound.binding
            batch.append((binding, [bool(value)] if binding.codec is None else binding.codec.encode(value)))
        client = self._client()
        unit = self.settings.unit
        for run in write_runs(batch):
            if run.table == "coil":
                request = (client.write_coil(run.start, run.values[0], device_id=unit) if len(run.values) == 1
                           else client.write_coils(run.start, list(run.values), device_id=unit))
            else:
                request = client.write_registers(run.start, list(run.values), device_id=unit)
            response = await self._request(request, f"writing {run.table} {run.start}..{run.start + len(run.values) - 1}")
            if response.isError():
                for index in run.items:
                    answers[index] = exception_text(int(response.exception_code))
        return answers

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "requests_per_poll": len(self.groups), "polls": self.polls}


def _short(error: Exception) -> str:
    text = str(error).replace("Modbus Error: ", "").strip()
    return text.split("\n")[0] or type(error).__name__
