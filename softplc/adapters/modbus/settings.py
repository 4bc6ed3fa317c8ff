"""Server settings of the Modbus TCP adapter: `servers.modbus` in tagdb.yaml, then CLI overrides."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from softplc.util.addresses import is_host
from softplc.util.durations import parse_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 5020  # 502 needs root; integrators point their client at 5020 or override
DEFAULT_UNIT_ID = 1
DEFAULT_STRING_WORDS = 16
DEFAULT_SYSTEM_BASE = 60000
# PLCs serve 8 (S7-1200, Lexium) to 32-64 (Modicon M340/M580) Modbus TCP connections; a plant's
# SCADA, HMI and historian need a handful. pymodbus itself has no limit.
DEFAULT_MAX_CONNECTIONS = 64
# A connection that sends nothing for this long is closed (0 = never); any request resets it.
DEFAULT_IDLE_TIMEOUT = 60.0


@dataclass(frozen=True)
class ModbusSettings:
    """Where and how the Modbus server serves (see docs/modbus.md)."""

    enabled: bool = True
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    unit_id: int = DEFAULT_UNIT_ID
    word_order: str = "big"
    string_words: int = DEFAULT_STRING_WORDS
    system_tags: bool = True
    system_base: int = DEFAULT_SYSTEM_BASE
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    idle_timeout: float = DEFAULT_IDLE_TIMEOUT

    @classmethod
    def from_servers(cls, servers: dict[str, Any]) -> ModbusSettings:
        """Settings from the `servers:` section (already checked by the schema).

        The server is on unless `servers.modbus` says `enabled: false`, like the OPC UA server:
        a plant without a `servers:` section serves both, on loopback and the default ports.
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
            max_connections=int(section.get("max_connections", DEFAULT_MAX_CONNECTIONS)),
            # A bad duration is reported with its location by settings_problems (softplc.adapters.modbus.section).
            idle_timeout=_seconds(section.get("idle_timeout", DEFAULT_IDLE_TIMEOUT)) or 0.0,
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


def settings_problems(config: PlantConfig) -> list[Problem]:
    """Located mistakes in `servers.modbus` that the schema cannot see (a duration's text, a host's form)."""
    section = config.section("servers", "modbus")
    if section is None:
        return []
    found: list[tuple[str, str]] = []
    if "idle_timeout" in section and _seconds(section["idle_timeout"]) is None:
        value = section["idle_timeout"]
        found.append(("idle_timeout", f"bad idle_timeout {value!r}: write a duration such as 60s or 5min, or 0 to never close idle connections"))
    if isinstance(section.get("host"), str) and not is_host(section["host"]):
        found.append(("host", f"bad host {section['host']!r}: write an IP address (127.0.0.1, 0.0.0.0, ::1) or a host name"))
    return [config.problem(("servers", "modbus", key), message) for key, message in found]


def _seconds(value: Any) -> float | None:
    try:
        return parse_duration(value)
    except (TypeError, ValueError):
        return None


