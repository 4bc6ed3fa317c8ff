"""The Modbus address map: which table and address serve each tag, derived from tagdb.yaml.

Allocation rule (stable across restarts; see docs/modbus.md):

- Each tag goes to a table by access and type unless `modbus: {table: ...}` says otherwise:
  rw bool → coils, ro bool → discrete inputs, rw numbers and strings → holding registers,
  ro numbers and strings → input registers.
- A tag with `modbus: {address: N}` is *pinned* at N and takes no part in the automatic packing.
- Every other tag is packed from address 0 of its table, in declaration order (the order
  `softplc tags` lists them), each right after the previous one. An automatic address
  therefore depends only on the unpinned tags declared before it in the same table: adding a
  tag at the end, or pinning a new one, never moves an existing tag.
- `_sys.` tags are packed the same way from `system_base` (default 60000) of each table, so
  plant tags added later never move them (those that do not fit below 65536 are left out,
  with a warning).
- Any overlap (pinned on pinned, pinned on packed, packed reaching the system block) is a
  configuration error with FILE:LINE:COL — never a silent move.
"""

from __future__ import annotations

import enum
import logging
from array import array
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from softplc.adapters.modbus.settings import ModbusSettings
from softplc.config.plant import SYSTEM_PREFIX, PlantConfig
from softplc.config.system_tags import runtime_tag_definitions
from softplc.config.yamlsource import ConfigError, Location, Problem, SourceMap
from softplc.core.datatypes import DataType
from softplc.core.tags import Access, TagDef
from softplc.protocols.modbus_codec import REGISTER_TYPES, RegisterCodec, register_words

ADDRESS_SPACE = 65536
log = logging.getLogger(__name__)


class Table(enum.Enum):
    """The four Modbus data tables."""

    COIL = "coil"
    DISCRETE_INPUT = "discrete_input"
    HOLDING = "holding"
    INPUT = "input"

    @property
    def is_bit(self) -> bool:
        return self in (Table.COIL, Table.DISCRETE_INPUT)

    @property
    def writable(self) -> bool:
        """Whether the protocol has function codes that write this table."""
        return self in (Table.COIL, Table.HOLDING)

    @property
    def prefix(self) -> str:
        """Leading digit of the classic reference notation (0xxxx, 1xxxx, 3xxxx, 4xxxx)."""
        return {Table.COIL: "0", Table.DISCRETE_INPUT: "1", Table.INPUT: "3", Table.HOLDING: "4"}[self]

    @property
    def plural(self) -> str:
        return {Table.COIL: "coils", Table.DISCRETE_INPUT: "discrete inputs", Table.HOLDING: "holding registers", Table.INPUT: "input registers"}[self]


_TABLE_NAMES = frozenset(table.value for table in Table)


@dataclass(frozen=True, slots=True)
class Mapping:
    """One tag's place in the map."""

    tag: TagDef
    table: Table
    address: int  # 0-based protocol address
    words: int  # registers (1 for a coil or discrete input)
    codec: RegisterCodec | None  # None for coils and discrete inputs
    pinned: bool = False

    @property
    def name(self) -> str:
        return self.tag.name

    @property
    def end(self) -> int:
        return self.address + self.words

    @property
    def number(self) -> int:
        """1-based register number (what mbpoll -r and most SCADA dialogs ask for)."""
        return self.address + 1

    @property
    def reference(self) -> str:
        """Classic reference, e.g. 40001 (5 digits up to 9999, 6 digits above: 410001)."""
        width = 4 if self.number <= 9999 else 5
        return f"{self.table.prefix}{self.number:0{width}d}"

    @property
    def encoding(self) -> str:
        return "bit" if self.codec is None else self.codec.describe()


class AddressMap:
    """Every served tag's table and address, with fast lookup by (table, address)."""

    def __init__(self, mappings: Sequence[Mapping], settings: ModbusSettings) -> None:
        self.mappings = list(mappings)
        self.settings = settings
        self.by_tag = {mapping.name: mapping for mapping in self.mappings}
        # Per table: address → index into self.mappings (-1 where nothing is mapped).
        self._owner: dict[Table, array] = {}
        for table in Table:
            size = max((m.end for m in self.mappings if m.table is table), default=0)
            self._owner[table] = array("i", [-1]) * size
        for index, mapping in enumerate(self.mappings):
            owner = self._owner[mapping.table]
            for address in range(mapping.address, mapping.end):
                owner[address] = index

    def __len__(self) -> int:
        return len(self.mappings)

    def in_table(self, table: Table) -> list[Mapping]:
        """Mappings of one table, by address."""
        return sorted((m for m in self.mappings if m.table is table), key=lambda m: m.address)

    def size(self, table: Table) -> int:
        """One past the highest mapped address of the table (0 when empty)."""
        return len(self._owner[table])

    def covering(self, table: Table, address: int, count: int) -> list[Mapping] | None:
        """The mappings touched by [address, address+count), or None if any address is unmapped.

        The first and last mapping may extend beyond the range (a partial value).
        """
        owner = self._owner[table]
        end = address + count
        if address < 0 or count < 1 or end > len(owner):
            return None
        mappings = self.mappings
        result: list[Mapping] = []
        current = address
        while current < end:
            index = owner[current]
            if index < 0:
                return None
            mapping = mappings[index]
            result.append(mapping)
            current = mapping.end
        return result

    def indices(self, table: Table, start: int, end: int) -> list[int]:
        """Indices (into `mappings`) of the mappings with any address in [start, end), in address order."""
        owner = self._owner[table]
        result: list[int] = []
        previous = -1
        for index in owner[max(0, start) : min(end, len(owner))]:
            if index >= 0 and index != previous:
                result.append(index)
                previous = index
        return result

    def runs(self, table: Table) -> list[tuple[int, int]]:
        """Contiguous mapped ranges of a table as (start, length)."""
        result: list[tuple[int, int]] = []
        for mapping in self.in_table(table):
            if result and result[-1][0] + result[-1][1] == mapping.address:
                start, length = result[-1]
                result[-1] = (start, length + mapping.words)
            else:
                result.append((mapping.address, mapping.words))
        return result


# -- building the map from a configuration ---------------------------------------------------


def build_address_map(config: PlantConfig, settings: ModbusSettings | None = None) -> AddressMap:
    """The address map of a plant; raises ConfigError (FILE:LINE:COL) for bad or overlapping options."""
    settings = settings or ModbusSettings.from_servers(config.servers)
    builder = _Builder(config, settings)
    return builder.build()


def tag_paths(config: PlantConfig) -> dict[str, tuple[Any, ...]]:
    """YAML path of each tag's declaration (a template's tag for its instances)."""
    paths: dict[str, tuple[Any, ...]] = {}
    raw = config.raw if isinstance(config.raw, dict) else {}
    templates = raw.get("templates") if isinstance(raw.get("templates"), dict) else {}
    for template_name, template in templates.items():
        tags = template.get("tags") if isinstance(template, dict) and isinstance(template.get("tags"), dict) else {}
        for instance in config.instances.get(template_name, []):
            for tag_name in tags:
                paths.setdefault(f"{instance}_{tag_name}", ("templates", template_name, "tags", tag_name))
    for tag_name in raw.get("tags") or {}:
        paths.setdefault(tag_name, ("tags", tag_name))
    return paths


class _Builder:
    def __init__(self, config: PlantConfig, settings: ModbusSettings) -> None:
        self.config = config
        self.settings = settings
        self.source = config.source or SourceMap(str(config.path))
        self.paths = tag_paths(config)
        self.problems: list[Problem] = []
        self.template_sizes = {("templates", name, "tags"): len(instances) for name, instances in config.instances.items()}
        self.overflow: dict[Table, list[Mapping]] = {}  # auto-allocated tags past the last address, per table

    def problem(self, tag: TagDef, key: str | None, message: str) -> None:
        """Report at the value of `modbus: {key: ...}`, or at the tag's name when key is None."""
        path = self.paths.get(tag.name)
        if path is None:
            self.problems.append(Problem(Location(self.source.file, 1, 1), f"{tag.name}: {message}"))
            return
        problem = self.source.problem((*path, "modbus", key), message) if key else self.source.problem(path, message, at_key=True)
        if problem not in self.problems:  # a template's tag reports once, not once per instance
            self.problems.append(problem)

    def where(self, mapping: Mapping) -> str:
        path = self.paths.get(mapping.name)
        if mapping.name.startswith(SYSTEM_PREFIX):
            return "system tag"
        if path is None:
            return "auto-allocated"
        location = self.source.value((*path, "modbus", "address")) if mapping.pinned else self.source.key(path)
        return f"{'pinned' if mapping.pinned else 'auto-allocated'}, {location}"

    def build(self) -> AddressMap:
        settings = self.settings
        user: list[Mapping] = []
        cursors = {table: 0 for table in Table}
        for tag in self.config.tags:
            mapping = self._place(tag, cursors)
            if mapping is not None:
                user.append(mapping)
        for table, left in self.overflow.items():
            # One message for all of them (a big template would otherwise give one per instance).
            first = left[0]
            more = f" and {len(left) - 1} more tag{'s' if len(left) > 2 else ''} after it" if len(left) > 1 else ""
            self.problem(first.tag, None,
                f"'{first.name}'{more} do{'' if more else 'es'} not fit the {table.plural} when packed automatically "
                f"('{first.name}' would need {first.address}..{first.end - 1}, beyond the last address 65535): leave tags out "
                "of Modbus (modbus: {enabled: false} on a tag or template), shorten strings (servers.modbus.string_words), "
                "or turn the Modbus server off (servers.modbus.enabled: false)")
        system: list[Mapping] = []
        if settings.system_tags:
            system_cursors = {table: settings.system_base for table in Table}
            left_out: list[str] = []
            for tag in runtime_tag_definitions(self.config):
                mapping = self._default_mapping(tag, system_cursors[_default_table(tag)], {}, pinned=False)
                if mapping is None:
                    continue
                if mapping.end > ADDRESS_SPACE:
                    # Diagnostics are not worth refusing to serve the plant: serve what fits.
                    left_out.append(tag.name)
                    continue
                system_cursors[mapping.table] = mapping.end
                system.append(mapping)
            if left_out:
                log.warning("%d _sys. tags (from %s on) do not fit above servers.modbus.system_base %d and are not "
                            "served over Modbus; lower system_base or string_words", len(left_out), left_out[0], settings.system_base)
            for mapping in user if not self.overflow else []:  # an overflow is already one message about the same tags
                if not mapping.pinned and mapping.end > settings.system_base:
                    self.problem(mapping.tag, None,
                        f"'{mapping.name}' would be auto-allocated at {mapping.table.plural} {mapping.address}..{mapping.end - 1}, "
                        f"into the _sys. tag block at {settings.system_base}: raise servers.modbus.system_base, "
                        "set system_tags: false, or pin tags with modbus: {address: N}")
                    break
        self._check_overlaps(user + system)
        if self.problems:
            raise ConfigError(self.problems)
        return AddressMap(user + system, settings)

    def _place(self, tag: TagDef, cursors: dict[Table, int]) -> Mapping | None:
        options = tag.options.get("modbus") or {}
        if not isinstance(options, dict) or options.get("enabled", True) is False:
            return None
        table = Table(options["table"]) if options.get("table") in _TABLE_NAMES else _default_table(tag)
        pinned = isinstance(options.get("address"), int)
        if pinned:
            path = self.paths.get(tag.name, ())
            instances = self.template_sizes.get(path[:3], 1) if path[:1] == ("templates",) else 1
            if instances > 1:
                self.problem(tag, "address", f"an address in a template would be shared by all {instances} instances; "
                             "leave template tags to automatic packing, or declare this tag per instance under 'tags:'")
                return None
        mapping = self._default_mapping(tag, options["address"] if pinned else cursors[table], options, pinned=pinned, table=table)
        if mapping is None:
            return None
        if mapping.end > ADDRESS_SPACE:
            if pinned:
                self.problem(tag, "address", f"'{tag.name}' needs {mapping.table.plural} {mapping.address}..{mapping.end - 1}, beyond the last address 65535")
            else:
                self.overflow.setdefault(mapping.table, []).append(mapping)
            return None
        if not pinned:
            cursors[table] = mapping.end
        return mapping

    def _default_mapping(self, tag: TagDef, address: int, options: dict[str, Any], *, pinned: bool, table: Table | None = None) -> Mapping | None:
        table = table or _default_table(tag)
        data_type = tag.type
        ok = True
        if table.is_bit:
            if data_type is not DataType.BOOL:
                self.problem(tag, "table", f"{table.plural} hold single bits: only bool tags, not {data_type.value} '{tag.name}'")
                return None
            for key in ("scale", "register_type", "words", "word_order"):
                if key in options:
                    self.problem(tag, key, f"'{key}' does not apply to {table.plural} (one bit per tag)")
                    ok = False
            return Mapping(tag, table, address, 1, None, pinned) if ok else None
        word_order = str(options.get("word_order", self.settings.word_order))
        if data_type is DataType.STRING:
            for key in ("scale", "register_type"):
                if key in options:
                    self.problem(tag, key, f"'{key}' does not apply to a string tag")
                    ok = False
            words = int(options.get("words", self.settings.string_words))
            codec = RegisterCodec(data_type, None, words, None, word_order)
            return Mapping(tag, table, address, words, codec, pinned) if ok else None
        if "words" in options:
            self.problem(tag, "words", f"'words' is only for string tags; the size of a {data_type.value} follows its register_type")
            ok = False
        scale = options.get("scale")
        if scale is not None and not data_type.is_numeric:
            self.problem(tag, "scale", f"'scale' needs a numeric tag, not {data_type.value}")
            ok = False
        if "register_type" in options:
            register_type = DataType(options["register_type"])
        elif data_type is DataType.BOOL:
            register_type = DataType.UINT16
        elif scale is not None and not data_type.is_integer:
            register_type = DataType.INT16
        else:
            register_type = data_type
        if register_type not in REGISTER_TYPES:
            self.problem(tag, "register_type", f"register_type {register_type.value} is not a register encoding")
            ok = False
        if scale is not None and register_type.is_float:
            self.problem(tag, "scale", f"'scale' needs an integer register_type, not {register_type.value}")
            ok = False
        if not ok:
            return None
        codec = RegisterCodec(data_type, register_type, register_words(register_type), float(scale) if scale is not None else None, word_order)
        return Mapping(tag, table, address, codec.words, codec, pinned)

    def _check_overlaps(self, mappings: Sequence[Mapping]) -> None:
        declared = {mapping.name: index for index, mapping in enumerate(mappings)}
        for table in Table:
            ordered = sorted((m for m in mappings if m.table is table), key=lambda m: m.address)
            reported: set[str] = set()
            reach: Mapping | None = None  # of the mappings so far, the one ending furthest
            for current in ordered:
                if reach is not None and current.address < reach.end:
                    # Blame a pinned tag (the user's explicit choice) over a packed one, else the later one.
                    if current.pinned != reach.pinned:
                        culprit, other = (current, reach) if current.pinned else (reach, current)
                    else:
                        culprit, other = sorted((current, reach), key=lambda m: declared[m.name], reverse=True)
                    if culprit.name not in reported:
                        reported.add(culprit.name)
                        self.problem(culprit.tag, "address" if culprit.pinned else None,
                            f"'{culprit.name}' ({table.plural} {_span(culprit)}) overlaps '{other.name}' "
                            f"({table.plural} {_span(other)}, {self.where(other)})")
                if reach is None or current.end > reach.end:
                    reach = current


def _span(mapping: Mapping) -> str:
    return str(mapping.address) if mapping.words == 1 else f"{mapping.address}..{mapping.end - 1}"


def _default_table(tag: TagDef) -> Table:
    writable = tag.access is Access.RW
    if tag.type is DataType.BOOL:
        return Table.COIL if writable else Table.DISCRETE_INPUT
    return Table.HOLDING if writable else Table.INPUT
