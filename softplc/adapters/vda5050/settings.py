"""The `vda5050:` section, resolved: the roadmap, the protocol, and the timing of faults."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.protocols.vda5050.topics import DEFAULT_INTERFACE, DEFAULT_VERSION
from softplc.util.durations import parse_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig

SECTION = "vda5050"
DURATIONS = {"lost_after": 60.0, "ack_timeout": 2.0, "tick": 0.1}


@dataclass(frozen=True)
class VdaSettings:
    """Resolved `vda5050:` (paths absolute, durations in seconds)."""

    roadmap: Path
    interface: str = DEFAULT_INTERFACE
    version: str = DEFAULT_VERSION
    lost_after: float = 60.0  # no state this long: the vehicle is lost (the spec's 30 s state interval, twice)
    ack_timeout: float = 2.0  # an order the state does not acknowledge this long is sent again, identically
    lookahead: int = 2  # nodes released ahead of a vehicle: the base beyond the node it stands on
    make_way: bool = True  # an idle vehicle standing in another's way is sent to a free node nearby
    tick: float = 0.1  # how often traffic, liveness and resends are looked at

    @classmethod
    def configured(cls, config: PlantConfig) -> bool:
        return isinstance(config.raw.get(SECTION), dict)

    @classmethod
    def from_config(cls, config: PlantConfig) -> VdaSettings:
        section: dict[str, Any] = config.raw.get(SECTION) or {}
        durations = {key: parse_duration(section[key]) if key in section else default for key, default in DURATIONS.items()}
        return cls(
            roadmap=config.base_dir / str(section.get("roadmap", "robots/roadmap.yaml")),
            interface=str(section.get("interface", DEFAULT_INTERFACE)),
            version=str(section.get("version", DEFAULT_VERSION)),
            lookahead=int(section.get("lookahead", 2)),
            make_way=bool(section.get("make_way", True)),
            **durations,
        )
