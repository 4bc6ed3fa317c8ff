"""Server settings of the Modbus TCP adapter: `servers.modbus` in tagdb.yaml, then CLI overrides."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
from typing import Any

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 5020  # 502 needs root; integrators point their client at 5020 or override
DEFAULT_UNIT_ID = 1
DEFAULT_STRING_WORDS = 16
DEFAULT_SYSTEM_BASE = 60000


@dataclass(frozen=True)
class ModbusSettings:
    """Where and how the Modbus server serves (see docs/modbus.md)."""

    enabled: bool = False
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    unit_id: int = DEFAULT_UNIT_ID
    word_order: str = "big"
    string_words: int = DEFAULT_STRING_WORDS
    system_tags: bool = True
    system_base: int = DEFAULT_SYSTEM_BASE

    @classmethod
    def from_servers(cls, servers: dict[str, Any]) -> ModbusSettings:
        """Settings from the `servers:` section (already checked by the schema).

        The server is enabled when a `modbus:` section exists and does not say `enabled: false`.
        """
        section = servers.get("modbus")
        if not isinstance(section, dict):
            return cls()
        return cls(
            enabled=bool(section.get("enabled", True)),
            host=str(section.get("host", DEFAULT_HOST)),
            port=int(section.get("port", DEFAULT_PORT)),
            unit_id=int(section.get("unit_id", DEFAULT_UNIT_ID)),
            word_order=str(section.get("word_order", "big")),
            string_words=int(section.get("string_words", DEFAULT_STRING_WORDS)),
            system_tags=bool(section.get("system_tags", True)),
            system_base=int(section.get("system_base", DEFAULT_SYSTEM_BASE)),
        )

    def override(self, *, host: str | None = None, port: int | None = None, disable: bool = False) -> ModbusSettings:
        """Apply command-line overrides; giving a host or port enables the server."""
        settings = self
        if host is not None:
            settings = replace(settings, host=host, enabled=True)
        if port is not None:
            settings = replace(settings, port=port, enabled=True)
        if disable:
            settings = replace(settings, enabled=False)
        return settings


def port_number(text: str) -> int:
    """argparse type for --modbus-port: an integer 0..65535 (0 = any free port)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port {port} is outside 0..65535")
    return port
