"""The handshake over Modbus TCP (pymodbus client), by polling.

Each role has an address `TABLE:ADDRESS[:TYPE]` (0-based), e.g. `holding:0`, `coil:12`,
`input:7:float64`. Roles in the same table are read with one request per table, so softplc's
handshake plant (all in holding registers 0–14) is one FC3 read per poll and one FC16 write
per answer (Ready and TaskID are adjacent).
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass
from typing import Any

from pymodbus.client import AsyncModbusTcpClient

from softplc.latency.driver import REQUIRED_ROLES, DriverError, PollingDriver, Snapshot

TABLES = {"coil": "coil", "coils": "coil", "discrete": "discrete", "discrete_input": "discrete",
          "holding": "holding", "hr": "holding", "input": "input", "ir": "input"}
WORDS = {"bool": 1, "int16": 1, "uint16": 1, "int32": 2, "uint32": 2, "float32": 2, "float64": 4}
FORMATS = {"int16": ">h", "uint16": ">H", "int32": ">i", "uint32": ">I", "float32": ">f", "float64": ">d"}
DEFAULT_TYPES = {"ready": "bool", "task_id": "uint16", "delay": "float64", "delay_scans": "uint32",
                 "handshakes": "uint32", "ready_stamp": "float64"}

# softplc's handshake plant, programs/handshake.yaml.
DEFAULT_ADDRESSES: dict[str, str] = {
    "ready": "holding:0",
    "task_id": "holding:1",
    "handshakes": "holding:3",
    "delay_scans": "holding:5",
    "delay": "holding:7",
    "ready_stamp": "holding:11",
}


@dataclass(frozen=True)
class Address:
    """Where one role lives: table, 0-based address, type."""

    table: str
    address: int
    type: str

    @property
    def size(self) -> int:
        return 1 if self.table in ("coil", "discrete") else WORDS[self.type]

    @classmethod
    def parse(cls, text: str, role: str) -> Address:
        parts = text.split(":")
        if len(parts) not in (2, 3) or parts[0].lower() not in TABLES or not parts[1].isdigit():
            raise DriverError(f"{role}: bad Modbus address {text!r}; write TABLE:ADDRESS[:TYPE], e.g. holding:0 or coil:5")
        table = TABLES[parts[0].lower()]
        kind = parts[2].lower() if len(parts) == 3 else DEFAULT_TYPES[role]
        if kind not in WORDS:
            raise DriverError(f"{role}: unknown type {kind!r}; expected one of: {', '.join(WORDS)}")
        if table in ("coil", "discrete") and kind != "bool":
            raise DriverError(f"{role}: a {table} holds a bool, not {kind}")
        address = int(parts[1])
        if address > 65535:
            raise DriverError(f"{role}: address {address} is above 65535")
        return cls(table, address, kind)


class ModbusDriver(PollingDriver):
    """A pymodbus TCP client polling the handshake registers."""

    def __init__(
        self,
        host: str,
        port: int,
        addresses: dict[str, str],
        *,
        unit_id: int = 1,
        word_order: str = "big",
        poll_interval: float = 0.001,
        timeout: float = 2.0,
    ) -> None:
        missing = [role for role in REQUIRED_ROLES if not addresses.get(role)]
        if missing:
            raise DriverError(f"no Modbus address for {', '.join(missing)}")
        self.addresses = {role: Address.parse(text, role) for role, text in addresses.items() if text}
        for role in ("ready", "task_id"):
            if self.addresses[role].table in ("discrete", "input"):
                raise DriverError(f"{role} must be writable: a coil or a holding register, not a {self.addresses[role].table}")
        self.host, self.port, self.unit_id = host, port, unit_id
        self.word_order = word_order
        self.poll_interval = poll_interval
        self.client = AsyncModbusTcpClient(host, port=port, timeout=timeout, retries=0)
        self._blocks = _blocks(self.addresses)
        self.description = f"Modbus TCP {host}:{port} unit {unit_id} (polling every {poll_interval * 1e3:g} ms)"

    @property
    def serves(self) -> set[str]:
        return set(self.addresses)

    async def connect(self) -> None:
        if not await self.client.connect():
            raise DriverError(f"cannot connect to Modbus TCP {self.host}:{self.port}")

    async def close(self) -> None:
        self.client.close()

    async def read(self) -> Snapshot:
        values: dict[str, Any] = {}
        for table, start, count, roles in self._blocks:
            data = await self._read_block(table, start, count)
            for role in roles:
                address = self.addresses[role]
                offset = address.address - start
                values[role] = self._decode(address, data[offset:offset + address.size])
        received = time.monotonic()
        return Snapshot(
            ready=bool(values["ready"]),
            task_id=_maybe(values.get("task_id"), int),
            delay=_maybe(values.get("delay"), float),
            delay_scans=_maybe(values.get("delay_scans"), int),
            handshakes=_maybe(values.get("handshakes"), int),
            ready_stamp=_maybe(values.get("ready_stamp"), float),
            received=received,
        )

    async def answer(self, task_id: int) -> None:
        ready, task = self.addresses["ready"], self.addresses["task_id"]
        task_words = self._encode(task, task_id)
        if ready.table == task.table == "holding" and ready.address + ready.size == task.address:
            await self._check(self.client.write_registers(ready.address, [0, *task_words], device_id=self.unit_id), "write Ready+TaskID")
            return
        if ready.table == task.table == "holding" and task.address + task.size == ready.address:
            await self._check(self.client.write_registers(task.address, [*task_words, 0], device_id=self.unit_id), "write TaskID+Ready")
            return
        # Separate requests: the TaskID first, so the PLC never sees Ready cleared without it.
        if task.table == "coil":
            await self._check(self.client.write_coil(task.address, bool(task_id), device_id=self.unit_id), "write TaskID")
        else:
            await self._check(self.client.write_registers(task.address, task_words, device_id=self.unit_id), "write TaskID")
        if ready.table == "coil":
            await self._check(self.client.write_coil(ready.address, False, device_id=self.unit_id), "clear Ready")
        else:
            await self._check(self.client.write_registers(ready.address, [0] * ready.size, device_id=self.unit_id), "clear Ready")

    async def _read_block(self, table: str, start: int, count: int) -> list[int]:
        client, unit = self.client, self.unit_id
        if table == "coil":
            response = await self._check(client.read_coils(start, count=count, device_id=unit), f"read coils {start}+{count}")
            return [int(bit) for bit in response.bits[:count]]
        if table == "discrete":
            response = await self._check(client.read_discrete_inputs(start, count=count, device_id=unit), f"read discrete inputs {start}+{count}")
            return [int(bit) for bit in response.bits[:count]]
        if table == "holding":
            response = await self._check(client.read_holding_registers(start, count=count, device_id=unit), f"read holding registers {start}+{count}")
        else:
            response = await self._check(client.read_input_registers(start, count=count, device_id=unit), f"read input registers {start}+{count}")
        return list(response.registers)

    async def _check(self, request: Any, what: str) -> Any:
        try:
            response = await request
        except Exception as error:
            raise DriverError(f"{what} failed: {error!r}") from None
        if response.isError():
            raise DriverError(f"{what} refused: {response}")
        return response

    def _decode(self, address: Address, words: list[int]) -> Any:
        if address.type == "bool":
            return bool(words[0])
        if self.word_order == "little":
            words = list(reversed(words))
        return struct.unpack(FORMATS[address.type], struct.pack(f">{len(words)}H", *words))[0]

    def _encode(self, address: Address, value: int) -> list[int]:
        if address.type == "bool":
            return [1 if value else 0]
        words = list(struct.unpack(f">{address.size}H", struct.pack(FORMATS[address.type], value)))
        return list(reversed(words)) if self.word_order == "little" else words


def _blocks(addresses: dict[str, Address]) -> list[tuple[str, int, int, list[str]]]:
    """Group roles into as few reads as possible (≤ 125 registers or 2000 bits per request)."""
    blocks: list[tuple[str, int, int, list[str]]] = []
    for table in ("holding", "input", "coil", "discrete"):
        roles = sorted((role for role, a in addresses.items() if a.table == table), key=lambda r: addresses[r].address)
        limit = 2000 if table in ("coil", "discrete") else 125
        current: list[str] = []
        start = end = 0
        for role in roles:
            address = addresses[role]
            if current and address.address + address.size - start <= limit:
                current.append(role)
                end = max(end, address.address + address.size)
                continue
            if current:
                blocks.append((table, start, end - start, current))
            current, start, end = [role], address.address, address.address + address.size
        if current:
            blocks.append((table, start, end - start, current))
    return blocks


def _maybe(value: Any, kind: type) -> Any:
    return None if value is None else kind(value)
