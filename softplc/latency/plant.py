"""The handshake plant `softplc latency` runs: programs/handshake.yaml with scan, scenario and servers applied."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from softplc.config import PlantConfig, import_program, parse_config

# programs/ sits next to the softplc package in a checkout (and in the sdist).
HANDSHAKE_YAML = Path(__file__).resolve().parents[2] / "programs" / "handshake.yaml"

SCENARIO_NAMES: tuple[str, ...] = ("slow", "average", "fast")


class PlantMissing(RuntimeError):
    """programs/handshake.yaml is not where softplc expects it."""


def scenario_durations(scenario: str, source: Path = HANDSHAKE_YAML) -> tuple[float, float, float]:
    """Task 1/2/3 durations in seconds, from the program itself (programs/handshake.py)."""
    cls = import_program("handshake.py:Handshake", source.parent)
    scenarios: dict[str, tuple[float, float, float]] = getattr(cls, "scenarios")
    if scenario not in scenarios:
        raise ValueError(f"unknown scenario {scenario!r}; expected one of: {', '.join(scenarios)}")
    return scenarios[scenario]


def handshake_config(
    scenario: str,
    scan: float,
    *,
    opcua_endpoint: str | None = None,
    modbus_port: int | None = None,
    opcua_extra: dict[str, Any] | None = None,
    source: Path = HANDSHAKE_YAML,
) -> PlantConfig:
    """The handshake plant at `scan` seconds running `scenario`, serving only the given servers."""
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"unknown scenario {scenario!r}; expected one of: {', '.join(SCENARIO_NAMES)}")
    if not source.exists():
        raise PlantMissing(f"the handshake plant {source} is missing (softplc latency runs it from a source checkout)")
    data = yaml.safe_load(source.read_text())
    interval = f"{scan * 1000:g}ms"
    task = data["tasks"]["handshake"]
    task["interval"] = interval
    # The program's watchdog trips only on a scan longer than this; its scans take ~50 µs.
    task["watchdog"] = f"{max(scan * 1000, 5):g}ms"
    task["programs"][0]["params"] = {"scenario": scenario, "scan_interval": interval}
    # Only the server under test runs: another one would compete for the CPU.
    servers: dict[str, Any] = {"opcua": {"enabled": False}, "modbus": {"enabled": False}, "hmi": {"enabled": False}}
    if opcua_endpoint is not None:
        servers["opcua"] = {**data["servers"].get("opcua", {}), "enabled": True, "endpoint": opcua_endpoint, **(opcua_extra or {})}
    if modbus_port is not None:
        servers["modbus"] = {**data["servers"].get("modbus", {}), "enabled": True, "host": "127.0.0.1", "port": modbus_port}
    data["servers"] = servers
    return parse_config(yaml.safe_dump(data, sort_keys=False), source)
