"""The plant two benchmarks share: a 10 ms probe task at priority 0 (its start latency is what is
measured) beside a `flood` task changing N float64 tags v00000… at every scan, servers off; each
benchmark adds the section it measures (history:, sparkplug:…)."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SUPPORT = REPO / "tests" / "history_support.py"  # the Flood program
CORE = REPO / "tests" / "core_programs.py"  # the Counter program


def tag_names(tags: int) -> list[str]:
    return [f"v{index:05d}" for index in range(tags)]


def flood_plant(name: str, tags: int, interval: str, section: str = "") -> str:
    """tagdb.yaml of the plant `name` with `tags` flooded every `interval`, then `section` as it is."""
    names = tag_names(tags)
    declared = "\n".join(f"  {tag}: {{type: float64}}" for tag in names)
    return f"""
version: 1
plant: {{name: {name}}}
tags:
  probe_count: {{type: uint32}}
  tick: {{type: uint32}}
{declared}
tasks:
  probe:
    interval: 10ms
    priority: 0
    programs:
      - {{name: probe, program: "{CORE}:Counter", bind: {{count: probe_count}}}}
  flood:
    interval: {interval}
    priority: 1
    programs:
      - {{name: flood, program: "{SUPPORT}:Flood", bind: {{tick: tick, values: [{", ".join(names)}]}}}}
servers: {{opcua: {{enabled: false}}, modbus: {{enabled: false}}, hmi: {{enabled: false}}}}
{section}"""
