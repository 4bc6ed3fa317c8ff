"""The `servers.modbus` section of tagdb.yaml and the `modbus:` key of each tag: schemas and checks."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.adapters.modbus.settings import ModbusSettings, settings_problems
from softplc.config.schema import DURATION, Section

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no Modbus TCP server (default true)."},
        "host": {"type": "string", "description": "Bind address (default 127.0.0.1)."},
        "port": {"type": "integer", "minimum": 0, "maximum": 65535, "description": "TCP port (default 5020; 0 = any free port, as under --sim)."},
        "unit_id": {"type": "integer", "minimum": 0, "maximum": 247, "description": "Unit id served (default 1)."},
        "word_order": {"enum": ["big", "little"], "description": "Order of the 16-bit words of 32/64-bit values."},
        "string_words": {"type": "integer", "minimum": 1, "maximum": 123, "description": "Registers per string tag (default 16)."},
        "system_tags": {"type": "boolean", "description": "Serve the _sys. tags (default true)."},
        "system_base": {"type": "integer", "minimum": 0, "maximum": 65535, "description": "First address of the _sys. tag block in each table (default 60000)."},
        "max_connections": {"type": "integer", "minimum": 1, "maximum": 4096, "description": "Most simultaneous client connections; more are refused (default 64)."},
        "idle_timeout": {**DURATION, "description": "Close a connection that sent nothing for this long; 0 = never (default 60s)."},
    },
    "additionalProperties": False,
}

TAG_SCHEMA: dict[str, Any] = {
    "description": "Modbus TCP mapping overrides for this tag.",
    "type": "object",
    "properties": {
        "table": {"enum": ["coil", "discrete_input", "holding", "input"], "description": "Register table."},
        "address": {"type": "integer", "minimum": 0, "maximum": 65535, "description": "0-based start address."},
        "scale": {"type": "number", "exclusiveMinimum": 0, "description": "Register = round(value * scale)."},
        "register_type": {
            "enum": ["int16", "uint16", "int32", "uint32", "float32", "float64"],
            "description": "The register encoding when it differs from the tag's type (e.g. a scaled float in int16).",
        },
        "words": {"type": "integer", "minimum": 1, "maximum": 123, "description": "Registers for a string tag (2 UTF-8 bytes each; 123 = one FC16 write)."},
        "word_order": {"enum": ["big", "little"], "description": "Word order of this tag's 32/64-bit value (default servers.modbus.word_order)."},
        "enabled": {"type": "boolean", "description": "false: not served over Modbus."},
    },
    "additionalProperties": False,
}


def problems(config: PlantConfig) -> list[Problem]:
    """Settings the schema cannot check, and the address map (overlaps, tables, encodings)."""
    found = settings_problems(config)
    settings = ModbusSettings.from_servers(config.servers)
    # Addresses pinned in the tags are checked even while the server is off.
    if settings.enabled or any("modbus" in tag.options for tag in config.tags):
        from softplc.adapters.modbus.address_map import build_address_map
        from softplc.config.yamlsource import ConfigError

        try:
            build_address_map(config, settings)
        except ConfigError as error:
            found.extend(error.problems)
    return found


SECTION = Section(path=("servers", "modbus"), schema=SCHEMA, tag_keys={"modbus": TAG_SCHEMA}, problems=problems)
