"""The `links:` section and the tags' `link:` key: schemas, `softplc check`'s problems, the `_sys.links.` tags and alarms.

Each link NAME adds diagnostic tags (served like the system tags, over every protocol):

    _sys.links.NAME.connected      bool     the remote answers (an alarm, link_NAME_down, is raised while it does not)
    _sys.links.NAME.state          string   connecting, up, late (no data for 2× the period), down
    _sys.links.NAME.error          string   why it is down, or the last problem with a bound tag ("" when none)
    _sys.links.NAME.bad_tags       uint32   tags read from the remote whose quality is not good
    _sys.links.NAME.reconnects     uint32   connections made after the first
    _sys.links.NAME.round_trip_ms  float64  the last poll's (Modbus) or heartbeat's (OPC UA) round trip
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.adapters.links.settings import (
    MAX_BITS,
    MAX_REGISTERS,
    PROTOCOLS,
    REGISTER_TYPE_NAMES,
    SECTION,
    SECURITY_MODES,
    TAG_KEY,
    read_links,
)
from softplc.config.schema import DURATION, NAME_PATTERN, Section
from softplc.core.datatypes import DataType
from softplc.core.tags import Access, TagDef

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

PREFIX = "_sys.links."

LINK_SCHEMA: dict[str, Any] = {
    "description": "A remote controller: an OPC UA server (endpoint) or a Modbus TCP server (host): docs/links.md.",
    "type": "object",
    "properties": {
        "protocol": {"enum": list(PROTOCOLS), "description": "opcua or modbus."},
        "enabled": {"type": "boolean", "description": "false: the link is not started (its tags keep their initial values, BAD)."},
        "period": {**DURATION, "description": "Modbus: the poll period; OPC UA: the publishing interval and heartbeat. "
                   "Bound tags go UNCERTAIN after 2x it without data, BAD after 5x (default 100ms)."},
        "timeout": {**DURATION, "description": "Longest wait for a connection or an answer (default 2s)."},
        "backoff_max": {**DURATION, "description": "Reconnect attempts back off from 0.5s, doubling up to this (default 30s)."},
        "endpoint": {"type": "string", "description": "OPC UA: opc.tcp://HOST:PORT[/PATH]."},
        "security": {"enum": list(SECURITY_MODES), "description": "OPC UA: None (default), Sign or SignAndEncrypt (Basic256Sha256)."},
        "certificate": {"type": "string", "description": "OPC UA: the client certificate (DER or PEM); default: one made in the state directory."},
        "private_key": {"type": "string", "description": "OPC UA: the client certificate's private key (PEM)."},
        "user": {"type": "string", "description": "OPC UA: the user name to log in with (default anonymous)."},
        "password_file": {"type": "string", "description": "OPC UA: a file whose first line is the password (relative to the plant file)."},
        "namespace": {"type": "string", "description": "OPC UA: the namespace URI {ns} stands for in node ids (default urn:softplc:tags if the server has it, else its last)."},
        "publishing_interval": {**DURATION, "description": "OPC UA: the subscription's publishing interval, 0 = at once (default: the period)."},
        "host": {"type": "string", "description": "Modbus: the server's address."},
        "port": {"type": "integer", "minimum": 1, "maximum": 65535, "description": "Modbus: TCP port (default 502)."},
        "unit": {"type": "integer", "minimum": 0, "maximum": 255, "description": "Modbus: unit id (default 1)."},
        "word_order": {"enum": ["big", "little"], "description": "Modbus: order of the words of 32/64-bit values (default big: most significant first)."},
        "max_registers": {"type": "integer", "minimum": 1, "maximum": MAX_REGISTERS, "description": "Modbus: most registers per read (default 125)."},
        "max_bits": {"type": "integer", "minimum": 1, "maximum": MAX_BITS, "description": "Modbus: most coils or inputs per read (default 2000)."},
        "gap": {"type": "integer", "minimum": 0, "maximum": MAX_REGISTERS, "description": "Modbus: unbound registers one read may span to save a request (default 0)."},
    },
    "required": ["protocol"],
    "additionalProperties": False,
}

SCHEMA: dict[str, Any] = {
    "description": "Other controllers whose OPC UA or Modbus TCP servers tags are bound to (a tag's link: key): docs/links.md.",
    "type": "object",
    "propertyNames": {"pattern": NAME_PATTERN},
    "additionalProperties": LINK_SCHEMA,
}

TAG_SCHEMA: dict[str, Any] = {
    "description": "Bind this tag to a remote controller of the links: section.",
    "type": "object",
    "properties": {
        "name": {"type": "string", "description": "The link (a key of links:)."},
        "source": {"type": "string", "description": "OPC UA: a node id (ns={ns};s=Name uses the link's namespace); Modbus: TABLE:ADDRESS, 0-based."},
        "direction": {"enum": ["in", "out", "both"], "description": "in: the remote's value (default); out: this tag's value goes to the remote; both."},
        "type": {"enum": list(REGISTER_TYPE_NAMES), "description": "Modbus: the register encoding when it differs from the tag's type."},
        "scale": {"type": "number", "exclusiveMinimum": 0, "description": "Modbus: register = round(value * scale)."},
        "word_order": {"enum": ["big", "little"], "description": "Modbus: word order of this value (default the link's)."},
        "words": {"type": "integer", "minimum": 1, "maximum": MAX_REGISTERS, "description": "Modbus: registers of a string tag (default 16)."},
    },
    "required": ["name", "source"],
    "additionalProperties": False,
}


def problems(config: PlantConfig) -> list[Problem]:
    """What the schema cannot say: unknown links, bad node ids and registers, overlaps, types a table cannot hold."""
    return read_links(config).problems


def link_names(config: PlantConfig) -> list[str]:
    section = config.section(SECTION)
    return [name for name, body in (section or {}).items() if isinstance(body, dict)]


def tag_definitions(name: str) -> list[TagDef]:
    """The diagnostic tags of link `name`."""
    prefix, group = f"{PREFIX}{name}.", f"_sys/links/{name}"

    def tag(key: str, data_type: DataType, initial: Any, description: str) -> TagDef:
        return TagDef(f"{prefix}{key}", data_type, initial, description=description, access=Access.RO, group=group, runtime_only=True)

    return [
        tag("connected", DataType.BOOL, False, f"link {name}: the remote answers"),
        tag("state", DataType.STRING, "connecting", f"link {name}: connecting, up, late (no data for 2x the period) or down"),
        tag("error", DataType.STRING, "", f"link {name}: why it is down, or the last problem with a bound tag"),
        tag("bad_tags", DataType.UINT32, 0, f"link {name}: tags read from the remote whose quality is not good"),
        tag("reconnects", DataType.UINT32, 0, f"link {name}: connections made after the first"),
        tag("round_trip_ms", DataType.FLOAT64, 0.0, f"link {name}: the last poll's or heartbeat's round trip in ms"),
    ]


def tags(config: PlantConfig) -> list[TagDef]:
    return [definition for name in link_names(config) for definition in tag_definitions(name)]


def alarms(config: PlantConfig) -> list[tuple[tuple[str | int, ...], dict[str, Any]]]:
    """One alarm per link: link_NAME_down while the remote does not answer."""
    section = config.section(SECTION) or {}
    found: list[tuple[tuple[str | int, ...], dict[str, Any]]] = []
    for name in link_names(config):
        if section[name].get("enabled", True) is False:
            continue
        prefix = f"{PREFIX}{name}."
        found.append(((SECTION, name), {
            "name": f"link_{name}_down",
            "discrete": {"tag": f"{prefix}connected", "value": False},
            "priority": "high",
            "message": f"link {name} is down: {{{prefix}error}}",
            "description": f"The remote controller of link {name} does not answer: its bound tags are BAD. It reconnects by itself.",
        }))
    return found


SECTION_OWNER = Section(path=(SECTION,), schema=SCHEMA, tag_keys={TAG_KEY: TAG_SCHEMA}, problems=problems, tags=tags, alarms=alarms)
