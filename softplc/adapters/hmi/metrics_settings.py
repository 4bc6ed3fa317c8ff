"""Who may scrape `/metrics`, and whether it is served: the `servers: hmi: metrics:` mapping.

    servers:
      hmi:
        metrics:
          enabled: true            # false: no /metrics
          anonymous: loopback      # Prometheus on this computer scrapes without credentials; off: never
          token_file: metrics.token   # a bearer token any address may scrape with (made on first start)

Prometheus scrapes without a browser session, so a scrape is let in by one of: a bearer token
(`Authorization: Bearer TOKEN`, the file's text; relative to the state directory, made with a
random token on first start when missing, mode 600), a request from a loopback address while
`anonymous: loopback` (the default), or a logged-in HMI session (a person looking). Anything else
is 401. Nothing here imports aiohttp or prometheus_client.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

METRICS_SCHEMA: dict[str, Any] = {
    "description": "Prometheus metrics at /metrics on the HMI's port (docs/operations.md, \"Metrics\").",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no /metrics (default true)."},
        "anonymous": {"enum": ["loopback", "off"], "description": "loopback (default): scrapes from this computer need no credentials; off: a token or a login is needed."},
        "token_file": {"type": "string", "description": "A bearer token file, relative to the state directory (made with a random token when missing)."},
    },
    "additionalProperties": False,
}


@dataclass(frozen=True)
class MetricsSettings:
    """Resolved `servers.hmi.metrics`."""

    enabled: bool = True
    anonymous_loopback: bool = True
    token_file: Path | None = None  # relative paths are in the state directory

    @classmethod
    def from_config(cls, config: PlantConfig) -> MetricsSettings:
        hmi = config.servers.get("hmi")
        section = hmi.get("metrics") if isinstance(hmi, dict) else None
        section = section if isinstance(section, dict) else {}
        token = section.get("token_file")
        return cls(
            enabled=bool(section.get("enabled", True)),
            anonymous_loopback=section.get("anonymous", "loopback") == "loopback",
            token_file=Path(token) if isinstance(token, str) and token else None,
        )

    def token_path(self, state_dir: Path) -> Path | None:
        if self.token_file is None:
            return None
        return self.token_file if self.token_file.is_absolute() else state_dir / self.token_file


def metrics_problems(config: PlantConfig) -> list[Problem]:
    """Mistakes of `servers.hmi.metrics` the schema cannot see: an empty token file name."""
    hmi = config.servers.get("hmi")
    section = hmi.get("metrics") if isinstance(hmi, dict) else None
    if not isinstance(section, dict) or section.get("token_file") != "":
        return []
    from softplc.config.yamlsource import Location, Problem

    path = ("servers", "hmi", "metrics", "token_file")
    message = "token_file is empty: name a file (e.g. metrics.token) or leave the key out"
    return [config.source.problem(path, message) if config.source else Problem(Location(str(config.path), 1, 1), message)]
