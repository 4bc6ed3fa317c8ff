"""The Modbus TCP adapter: serves the tag database through pymodbus 3.16 (SimDevice datastore).

Reads return the tag database's current values (the register image is refreshed on every
read). Writes are decoded per tag and submitted with `db.submit(..., atomic=True)`, validated
exactly like an OPC UA write (Modbus clients write with the operator role, their Origin names
the connection's host:port): only if every tag of the request is valid are they journaled
(applied at the next cycle boundary). Only the ten data function codes and FC43/14 device
identification are served (functions.py); the connections frame the byte stream, are capped
and closed when idle or on a framing error (connections.py, framing.py).
Exception codes (see docs/modbus.md):

    01 illegal function      a function code softplc does not serve
    02 illegal data address  unmapped address, read-only tag, a write covering part of a value
    03 illegal data value    bad quantity or truncated request, wrong type (e.g. 2 for a bool), outside min/max, bad string
    04 server device failure an internal error while serving the request (logged)
    0B gateway no response   a unit id other than servers.modbus.unit_id (checked first, for every function)
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType as SimType
from pymodbus.simulator import SimData, SimDevice

from softplc.adapters.modbus import lognoise
from softplc.adapters.modbus.address_map import AddressMap, Table, build_address_map
from softplc.adapters.modbus.connections import ConnectionCounts, PlcTcpServer, request_peer
from softplc.adapters.modbus.functions import RequestDecoder
from softplc.adapters.modbus.identification import device_objects, identification_request
from softplc.adapters.modbus.image import RegisterImage
from softplc.adapters.modbus.requests import LIMITS, RequestGuard, guarded_requests
from softplc.adapters.modbus.settings import ModbusSettings, settings_problems
from softplc.config import PlantConfig
from softplc.config.yamlsource import ConfigError
from softplc.core.plant import AdapterError, Plant
from softplc.core.tagdb import Origin, Rule, TagDatabase
from softplc.protocols.modbus_codec import CodecError
from softplc.util.plurals import plural

log = logging.getLogger(__name__)

EXCEPTION_FOR_RULE: dict[Rule, ExcCodes] = {
    Rule.UNKNOWN_TAG: ExcCodes.ILLEGAL_ADDRESS,
    # A read-only tag is "not an allowable address" for a write (what PLCs answer, and what
    # pymodbus itself answers for readonly registers); 04 would claim the server failed.
    Rule.READ_ONLY: ExcCodes.ILLEGAL_ADDRESS,
    Rule.TYPE_MISMATCH: ExcCodes.ILLEGAL_VALUE,
    Rule.OUT_OF_RANGE: ExcCodes.ILLEGAL_VALUE,
    Rule.ACCESS_DENIED: ExcCodes.ILLEGAL_ADDRESS,
    Rule.INVALID_REQUEST: ExcCodes.ILLEGAL_ADDRESS,
    # Forced by an engineer: not writable until unforced, like a read-only tag. Not 04 (the server
    # did not fail) nor 06 "busy" (the client would retry a write that cannot succeed).
    Rule.FORCED: ExcCodes.ILLEGAL_ADDRESS,
    # The standby of a redundant pair: "busy, retry later" — the client should write to the
    # active (docs/redundancy.md); Modbus has no way to name it.
    Rule.NOT_ACTIVE: ExcCodes.DEVICE_BUSY,
}
# The read that pymodbus does after FC5/FC6 builds the echo of the request: leave the
# just-written words in place instead of refreshing them from the (not yet applied) tag.
_ECHO_READS = (5, 6)


class ModbusAdapter:
    """Modbus TCP server over the tag database (one unit id, four tables)."""

    name = "modbus"

    def __init__(self, config: PlantConfig, settings: ModbusSettings | None = None) -> None:
        problems = settings_problems(config)
        self.settings = settings or ModbusSettings.from_servers(config.servers)
        # Built now so a bad map is a configuration error before anything starts.
        try:
            self.map: AddressMap = build_address_map(config, self.settings)
        except ConfigError as error:
            problems.extend(error.problems)
        if problems:
            raise ConfigError(problems)
        self._plant_name = config.name
        self.port: int | None = None
        self._server: PlcTcpServer | None = None
        self._image: RegisterImage | None = None
        self._db: TagDatabase | None = None
        self._unsubscribe: Callable[[], None] | None = None
        self._remove_log_filter: Callable[[], None] | None = None

    @property
    def host(self) -> str:
        return self.settings.host

    async def start(self, plant: Plant) -> None:
        db = plant.tags
        missing = [mapping.name for mapping in self.map.mappings if mapping.name not in db]
        if missing:
            raise AdapterError(f"Modbus map names tags the plant does not have: {', '.join(missing[:5])}")
        settings = self.settings
        _probe_port(settings.host, settings.port)
        self._db = db
        self._image = RegisterImage(self.map, db)
        self._unsubscribe = db.on_change(self._image.note_changed)
        device = SimDevice(settings.unit_id, simdata=self._simdata(), action=self._action)
        guard = RequestGuard(self.map, settings.unit_id)
        served = [*guarded_requests(guard), identification_request(guard, device_objects(self._plant_name))]
        server = PlcTcpServer(
            device,
            address=(settings.host, settings.port),
            decoder=RequestDecoder(served, guard),
            max_connections=settings.max_connections,
            idle_timeout=settings.idle_timeout,
        )
        try:
            await server.serve_forever(background=True)
        except (RuntimeError, OSError) as error:
            self._stop_watching()
            raise AdapterError(f"Modbus TCP cannot listen on {settings.host}:{settings.port}: {error}") from None
        self._server = server
        self._remove_log_filter = lognoise.install()
        sockets = getattr(server.transport, "sockets", None) or []
        self.port = sockets[0].getsockname()[1] if sockets else settings.port
        log.debug("Modbus TCP serving %s on %s:%s unit %d", plural(len(self.map), "tag"), settings.host, self.port, settings.unit_id)

    async def stop(self) -> None:
        self._stop_watching()
        server, self._server = self._server, None
        if server is not None:
            await server.shutdown()

    def connections(self) -> ConnectionCounts:
        """Open client connections, and how many were refused, closed for idleness or for a framing error."""
        if self._server is None:
            return ConnectionCounts(0, 0, 0, 0)
        return self._server.counts

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py): connections and requests."""
        server = self._server
        if server is None:
            return {}
        counts = server.counts
        return {
            "connections": counts.open,
            "connections_refused": counts.refused,
            "connections_closed": {"idle": counts.closed_idle, "framing": counts.closed_framing},
            "requests": {(str(function), result): count for (function, result), count in server.requests.items()},
        }

    def describe(self) -> str:
        counts = ", ".join(plural(sum(m.words for m in self.map.in_table(t)), t.value.replace("_", " ") if t.is_bit else f"{t.value} register",
                                  t.plural) for t in Table)
        where = f"{self.settings.host}:{self.port if self.port is not None else self.settings.port}"
        return f"Modbus TCP on {where} unit {self.settings.unit_id} ({plural(len(self.map), 'tag')}: {counts}; see softplc modbus-map)"

    def _stop_watching(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._remove_log_filter is not None:
            self._remove_log_filter()
            self._remove_log_filter = None

    def _simdata(self) -> tuple[list[SimData], list[SimData], list[SimData], list[SimData]]:
        """One SimData per contiguous mapped run of each table (gaps stay invalid → 02)."""
        blocks: list[list[SimData]] = []
        for table in (Table.COIL, Table.DISCRETE_INPUT, Table.HOLDING, Table.INPUT):
            runs = self.map.runs(table)
            if table.is_bit:
                entries = [SimData(start, values=[False] * length, datatype=SimType.BITS) for start, length in runs]
                # pymodbus needs at least one entry; the request guard rejects every address of an empty table.
                blocks.append(entries or [SimData(0, values=[False], datatype=SimType.BITS)])
            else:
                entries = [SimData(start, values=[0] * length, datatype=SimType.REGISTERS) for start, length in runs]
                blocks.append(entries or [SimData(0, datatype=SimType.INVALID)])
        return blocks[0], blocks[1], blocks[2], blocks[3]

    async def _action(
        self, function_code: int, start: int, address: int, count: int, registers: list[int], values: list[Any] | None
    ) -> ExcCodes | None:
        """SimDevice hook, called before pymodbus reads or writes its register block."""
        try:
            table = LIMITS[function_code][0]
            if values is None:
                if function_code not in _ECHO_READS:
                    self._refresh(table, start, address, count, registers)
                return None
            return self._write(table, address, list(values))
        except Exception:  # never let one request take the server down; say what happened
            log.exception("Modbus request (function %d, address %d) failed", function_code, address)
            return ExcCodes.DEVICE_FAILURE

    def _refresh(self, table: Table, start: int, address: int, count: int, registers: list[int]) -> None:
        assert self._image is not None
        # For coils and discrete inputs pymodbus passes the 16-bit word index of its block and
        # the number of words the request touches.
        first = address // 16 if table.is_bit else address
        self._image.refresh(table, first, count, registers, first - start)

    def _write(self, table: Table, address: int, values: list[Any]) -> ExcCodes | None:
        """Validate every tag the write covers; submit them all, or nothing."""
        assert self._db is not None
        db = self._db
        origin = Origin("modbus", peer=request_peer.get())  # the connection's "host:port", for the audit trail
        end = address + len(values)
        mappings = self.map.covering(table, address, len(values))
        if mappings is None:
            return ExcCodes.ILLEGAL_ADDRESS
        items: list[tuple[str, Any]] = []
        for mapping in mappings:
            if mapping.address < address or mapping.end > end:
                detail = f"the write {table.value} {address}..{end - 1} covers part of it ({mapping.address}..{mapping.end - 1})"
                log.debug("Modbus write to %s refused: %s", mapping.name, detail)
                db.refused(origin, mapping.name, None, Rule.INVALID_REQUEST, detail)
                return ExcCodes.ILLEGAL_ADDRESS
            words = values[mapping.address - address : mapping.end - address]
            try:
                value = bool(words[0]) if mapping.codec is None else mapping.codec.decode(words)
            except CodecError as error:
                log.debug("Modbus write to %s refused: %s", mapping.name, error)
                db.refused(origin, mapping.name, list(words), Rule.TYPE_MISMATCH, str(error))
                return ExcCodes.ILLEGAL_VALUE
            items.append((mapping.name, value))
        # All of the request or nothing: one refused tag refuses the whole write.
        for result in db.submit(items, origin, atomic=True):
            if result is not None:
                log.debug("Modbus write refused: %s", result)
                return EXCEPTION_FOR_RULE[result.rule]
        return None


def _probe_port(host: str, port: int) -> None:
    """Raise AdapterError with the OS's reason if (host, port) cannot be bound (pymodbus hides it)."""
    if port == 0:
        return
    try:
        infos = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as error:
        raise AdapterError(f"Modbus TCP host {host!r}: {error}") from None
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's server does
        try:
            probe.bind(address)
        except OSError as error:
            reason = "port in use" if error.errno in (98, 48) else error.strerror or str(error)
            raise AdapterError(f"Modbus TCP cannot listen on {host}:{port}: {reason} ({error})") from None
