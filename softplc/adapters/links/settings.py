"""The `links:` section and the tags' `link:` keys, resolved: one `LinkSettings` per remote, one `Binding` per bound tag.

    links:
      line2:                                     # OPC UA: another softplc, a TwinCAT, an S7-1500...
        protocol: opcua
        endpoint: opc.tcp://10.0.0.5:4840/softplc/
        security: SignAndEncrypt                 # None (default), Sign or SignAndEncrypt (Basic256Sha256)
        user: line1
        password_file: line2.password            # its first line; relative to the plant file
        period: 100ms                            # publishing interval, and the quality's time base
      press:                                     # Modbus TCP
        protocol: modbus
        host: 10.0.0.6
        port: 502
        unit: 1
        word_order: big
        period: 100ms                            # the poll period

    tags:
      line2_ready: {type: bool, link: {name: line2, source: "ns={ns};s=Ready", direction: both}}
      press_force: {type: float32, link: {name: press, source: "holding:100", type: int16, scale: 10}}

Everything here is plain data: nothing imports asyncua or pymodbus (a section is read whenever a
configuration is checked). `read_links` collects located problems as it goes, so `softplc check`
and the adapter read the file the same way.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import urlparse

from softplc.core.datatypes import DataType
from softplc.core.tags import TagDef
from softplc.protocols.modbus_codec import RegisterCodec, register_words
from softplc.util.addresses import is_host
from softplc.util.durations import parse_duration
from softplc.util.suggest import did_you_mean

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SECTION = "links"
TAG_KEY = "link"
PROTOCOLS = ("opcua", "modbus")
SECURITY_MODES = ("None", "Sign", "SignAndEncrypt")
TABLES = ("coil", "discrete_input", "holding", "input")
REGISTER_TYPE_NAMES = ("int16", "uint16", "int32", "uint32", "float32", "float64", "string")
DEFAULT_PERIOD = 0.1
DEFAULT_TIMEOUT = 2.0
DEFAULT_BACKOFF_MAX = 30.0
MAX_REGISTERS = 125  # FC3/FC4 read at most 125 registers (Modbus spec)
MAX_BITS = 2000  # FC1/FC2 read at most 2000 bits
DEFAULT_STRING_WORDS = 16

OPCUA_KEYS = frozenset({"endpoint", "security", "certificate", "private_key", "user", "password_file", "namespace", "publishing_interval"})
MODBUS_KEYS = frozenset({"host", "port", "unit", "word_order", "max_registers", "max_bits", "gap"})
MODBUS_BINDING_KEYS = frozenset({"type", "scale", "word_order", "words"})
# ns=2;s=Name, ns={ns};i=7, nsu=urn:x;s=Name, i=2258, s=Name, g=GUID, b=BASE64
_NODE_ID = re.compile(r"^(?:(?:ns=(?:\d+|\{ns\})|nsu=[^;]+);)?(?:i=\d+|s=.+|g=[0-9A-Fa-f-]{36}|b=[A-Za-z0-9+/=]+)$", re.S)
_REGISTER = re.compile(r"^([a-z_]+):(\d+)$")


class Direction(enum.Enum):
    """Which way a bound tag's value goes: in from the remote, out to it, or both."""

    IN = "in"
    OUT = "out"
    BOTH = "both"

    @property
    def reads(self) -> bool:
        return self is not Direction.OUT

    @property
    def writes(self) -> bool:
        return self is not Direction.IN


@dataclass(frozen=True)
class Binding:
    """One tag bound to a remote: a node id (OPC UA) or a register (Modbus) with its encoding."""

    tag: TagDef
    link: str
    source: str  # as written: a node id (with {ns}) or TABLE:ADDRESS
    direction: Direction
    path: tuple[Any, ...] = ()  # the `link:` key's place in the file, for errors found at start
    table: str = ""  # Modbus: coil, discrete_input, holding, input
    address: int = 0  # Modbus: 0-based
    codec: RegisterCodec | None = None  # Modbus registers (None for coils and discrete inputs)

    @property
    def size(self) -> int:
        """Registers (or bits) the binding takes on a Modbus remote."""
        return self.codec.words if self.codec is not None else 1

    @property
    def name(self) -> str:
        return self.tag.name


@dataclass(frozen=True)
class LinkSettings:
    """One remote controller and the tags bound to it."""

    name: str
    protocol: str
    period: float = DEFAULT_PERIOD
    timeout: float = DEFAULT_TIMEOUT
    backoff_max: float = DEFAULT_BACKOFF_MAX
    enabled: bool = True
    bindings: tuple[Binding, ...] = ()
    path: tuple[Any, ...] = ()
    # OPC UA
    endpoint: str = ""
    security: str = "None"
    certificate: Path | None = None
    private_key: Path | None = None
    user: str | None = None
    password_file: Path | None = None
    namespace: str | None = None
    publishing_interval: float | None = None  # None: the period
    # Modbus TCP
    host: str = ""
    port: int = 502
    unit: int = 1
    word_order: str = "big"
    max_registers: int = MAX_REGISTERS
    max_bits: int = MAX_BITS
    gap: int = 0  # unbound registers a grouped read may span (0: contiguous only)

    @property
    def address(self) -> str:
        """Where the remote is, for messages and the `_sys.links.` tags."""
        return self.endpoint if self.protocol == "opcua" else f"{self.host}:{self.port} unit {self.unit}"

    def password(self) -> str | None:
        """The password file's first line (read at each connect, so a changed file takes effect on reconnect)."""
        if self.password_file is None:
            return None
        lines = self.password_file.read_text(encoding="utf-8").splitlines()
        return lines[0] if lines else ""


@dataclass
class Links:
    """Every link of a configuration and the problems found reading them."""

    links: dict[str, LinkSettings] = field(default_factory=dict)
    problems: list[Problem] = field(default_factory=list)


def read_links(config: PlantConfig) -> Links:
    """The links and their bindings of a (core-valid) configuration, with located problems."""
    found = Links()
    raw = config.raw.get(SECTION)
    sections = raw if isinstance(raw, dict) else {}
    bindings: dict[str, list[Binding]] = {name: [] for name in sections}
    for tag in config.tags:
        options = tag.options.get(TAG_KEY)
        if not isinstance(options, dict):
            continue
        path = config.option_path(tag.name, TAG_KEY)
        name = str(options.get("name", ""))
        if name not in sections:
            known = ", ".join(sorted(sections)) or "none: add a links: section"
            found.problems.append(config.problem((*path, "name"), f"unknown link {name!r}{did_you_mean(name, sections)} (links: {known})"))
            continue
        protocol = sections[name].get("protocol") if isinstance(sections[name], dict) else None
        binding = _binding(config, tag, options, path, str(protocol), sections[name], found.problems)
        if binding is not None:
            bindings[name].append(binding)
    for name, section in sections.items():
        if not isinstance(section, dict):
            continue
        settings = _link(config, name, section, tuple(bindings[name]), found.problems)
        if settings is not None:
            found.links[name] = settings
            found.problems.extend(_overlaps(config, settings))
    return found


def _link(config: PlantConfig, name: str, section: dict[str, Any], bindings: tuple[Binding, ...],
          problems: list[Problem]) -> LinkSettings | None:
    path = (SECTION, name)

    def problem(key: str, message: str) -> None:
        problems.append(config.problem((*path, key) if key else path, message))

    protocol = str(section.get("protocol"))
    own, other = (OPCUA_KEYS, MODBUS_KEYS) if protocol == "opcua" else (MODBUS_KEYS, OPCUA_KEYS)
    for key in sorted(other & section.keys()):
        problem(key, f"{key} is for {'a Modbus' if protocol == 'opcua' else 'an OPC UA'} link; link {name} is {protocol}")
    durations: dict[str, float] = {}
    for key, default, zero in (("period", DEFAULT_PERIOD, False), ("timeout", DEFAULT_TIMEOUT, False),
                               ("backoff_max", DEFAULT_BACKOFF_MAX, False), ("publishing_interval", -1.0, True)):
        if key not in section:
            durations[key] = default
            continue
        seconds = _seconds(section[key])
        if seconds is None or seconds < 0 or (seconds == 0 and not zero):
            problem(key, f"bad {key} {section.get(key)!r}: write a duration such as 100ms or 2s" + (" (0: as fast as the server publishes)" if zero else ""))
            seconds = default
        durations[key] = seconds

    def file(key: str) -> Path | None:
        text = section.get(key)
        if not text:
            return None
        resolved = config.base_dir / str(text)
        if not resolved.is_file():
            problem(key, f"file not found: {resolved}")
        return resolved

    settings = LinkSettings(
        name=name, protocol=protocol, period=durations["period"], timeout=durations["timeout"],
        backoff_max=durations["backoff_max"], enabled=bool(section.get("enabled", True)), bindings=bindings, path=path,
    )
    if protocol == "opcua":
        endpoint = str(section.get("endpoint", ""))
        url = urlparse(endpoint)
        try:
            port = url.port
        except ValueError:
            port = None
        if url.scheme != "opc.tcp" or not url.hostname or not is_host(url.hostname) or port is None:
            problem("endpoint" if "endpoint" in section else "", f"link {name} needs endpoint: opc.tcp://HOST:PORT[/PATH], not {endpoint!r}"
                    if endpoint else f"link {name} needs an endpoint: opc.tcp://HOST:PORT[/PATH]")
        if section.get("password_file") and not section.get("user"):
            problem("password_file", "a password_file needs a user")
        if bool(section.get("certificate")) != bool(section.get("private_key")):
            problem("certificate" if section.get("certificate") else "private_key", "certificate and private_key go together")
        publishing = durations["publishing_interval"]
        return replace(
            settings, endpoint=endpoint, security=str(section.get("security", "None")), certificate=file("certificate"),
            private_key=file("private_key"), user=section.get("user"), password_file=file("password_file"),
            namespace=section.get("namespace"), publishing_interval=None if publishing < 0 else publishing,
        )
    host = str(section.get("host", ""))
    if not host or not is_host(host):
        problem("host" if "host" in section else "", f"link {name} needs a host: an IP address or host name" + (f", not {host!r}" if host else ""))
    return replace(
        settings, host=host, port=int(section.get("port", 502)), unit=int(section.get("unit", 1)),
        word_order=str(section.get("word_order", "big")), max_registers=int(section.get("max_registers", MAX_REGISTERS)),
        max_bits=int(section.get("max_bits", MAX_BITS)), gap=int(section.get("gap", 0)),
    )


def _binding(config: PlantConfig, tag: TagDef, options: dict[str, Any], path: tuple[Any, ...], protocol: str,
             section: dict[str, Any], problems: list[Problem]) -> Binding | None:
    def problem(key: str, message: str) -> None:
        problems.append(config.problem((*path, key), message))

    source = str(options.get("source", ""))
    direction = Direction(options.get("direction", "in"))
    base = Binding(tag, str(options["name"]), source, direction, path)
    if protocol == "opcua":
        extra = sorted(MODBUS_BINDING_KEYS & options.keys())
        if extra:
            problem(extra[0], f"{extra[0]} is for a Modbus register; link {base.link} is OPC UA (the node's own type is used)")
            return None
        if not _NODE_ID.match(source):
            problem("source", f"bad node id {source!r}: write ns=2;s=Name, ns={{ns}};s=Name (the link's namespace), nsu=URI;s=Name or i=2258")
            return None
        return base
    match = _REGISTER.match(source)
    if match is None or match.group(1) not in TABLES:
        table = match.group(1) if match else ""
        hint = did_you_mean(table, TABLES) if table else ""
        problem("source", f"bad register {source!r}{hint}: write TABLE:ADDRESS (0-based), TABLE one of {', '.join(TABLES)}")
        return None
    table, address = match.group(1), int(match.group(2))
    if direction.writes and table in ("discrete_input", "input"):
        what = "discrete inputs are" if table == "discrete_input" else "input registers are"
        problem("direction", f"{what} read-only in Modbus: direction {direction.value} needs a coil or holding register")
        return None
    if table in ("coil", "discrete_input"):
        extra = sorted(MODBUS_BINDING_KEYS & options.keys())
        if extra:
            problem(extra[0], f"{extra[0]} is for registers; a {table} is one bit")
            return None
        if tag.type is not DataType.BOOL:
            problem("source", f"a {table} is one bit: tag {tag.name} must be bool, not {tag.type.value} (or bind a holding or input register)")
            return None
        return Binding(tag, base.link, source, direction, path, table, address, None)
    codec = _codec(tag, options, str(section.get("word_order", "big")), problem)
    if codec is None:
        return None
    if address + codec.words > 65536:
        problem("source", f"{tag.name} takes {codec.words} registers from {address}: beyond the last address 65535")
        return None
    return Binding(tag, base.link, source, direction, path, table, address, codec)


def _codec(tag: TagDef, options: dict[str, Any], word_order: str, problem: Any) -> RegisterCodec | None:
    """The register encoding of a tag bound to a holding or input register."""
    written = options.get("type")
    scale = options.get("scale")
    order = str(options.get("word_order", word_order))
    if tag.type is DataType.STRING or written == "string":
        if tag.type is not DataType.STRING or written not in (None, "string") or scale is not None:
            problem("type", f"a string register block needs a string tag (tag {tag.name} is {tag.type.value})" if tag.type is not DataType.STRING
                    else "a string tag is read as type string, without scale")
            return None
        return RegisterCodec(DataType.STRING, None, int(options.get("words", DEFAULT_STRING_WORDS)), None, order)
    if "words" in options:
        problem("words", "words is for a string tag")
        return None
    if written is None:
        register_type = DataType.UINT16 if tag.type is DataType.BOOL else tag.type
    else:
        register_type = DataType(written)
    if tag.type is DataType.BOOL and (register_type.is_float or scale is not None):
        problem("type", f"a bool tag is read from an integer register (0 or 1), not {register_type.value}" + (" with a scale" if scale else ""))
        return None
    if tag.type.is_integer and register_type.is_float and scale is None:
        problem("type", f"tag {tag.name} is {tag.type.value}: a {register_type.value} register needs the tag to be a float too (or a scale)")
        return None
    return RegisterCodec(tag.type, register_type, register_words(register_type), float(scale) if scale is not None else None, order)


def _overlaps(config: PlantConfig, settings: LinkSettings) -> list[Problem]:
    """Two tags on one register (Modbus) or one node (OPC UA) of the same link."""
    found: list[Problem] = []
    if settings.protocol == "opcua":
        seen: dict[str, Binding] = {}
        for binding in settings.bindings:
            other = seen.setdefault(binding.source, binding)
            if other is not binding:
                found.append(config.problem((*binding.path, "source"), f"node {binding.source} of link {settings.name} is bound twice: "
                                            f"to {other.name} and {binding.name}"))
        return found
    for table in TABLES:
        spans = sorted((b for b in settings.bindings if b.table == table), key=lambda b: b.address)
        reaching: Binding | None = None  # the binding reaching furthest so far
        for binding in spans:
            if reaching is not None and binding.address < reaching.address + reaching.size:
                last = reaching.address + reaching.size - 1
                found.append(config.problem((*binding.path, "source"), f"register overlap on link {settings.name}: {binding.name} at "
                                            f"{table}:{binding.address} overlaps {reaching.name} ({table}:{reaching.address}..{last})"))
            if reaching is None or binding.address + binding.size > reaching.address + reaching.size:
                reaching = binding
    return found


def _seconds(value: Any) -> float | None:
    try:
        return parse_duration(value)
    except (TypeError, ValueError):
        return None
