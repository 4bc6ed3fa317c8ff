"""HMI settings: the `servers: hmi:` section (where and how it serves) and the `hmi:` section (views).

Both sections' JSON Schema fragments are plain data here (`HMI_SERVER`, `HMI_SECTION`), wired
into `softplc.config.schema`; what a schema cannot say (a duration's form, a host name, files that
must exist, user views bound to tags and SVG ids) is checked by `hmi_problems(config)`, which
returns located `Problem`s for `softplc check` and `softplc run`. Nothing here imports aiohttp.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.adapters.hmi.metrics_settings import METRICS_SCHEMA, metrics_problems
from softplc.core.roles import Role
from softplc.util.addresses import is_host
from softplc.util.durations import parse_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
DEFAULT_UPDATE_RATE = 10.0  # updates of each value per second and client (FUXA polls every 1-3 s; a screen refreshes at 60)
DEFAULT_HEARTBEAT = 2.0  # s between heartbeats each way; a silent peer is gone after 2.5 of them
DEFAULT_SESSION_TIMEOUT = 8 * 3600.0  # idle seconds before a login expires (one shift)
DEFAULT_MAX_CLIENTS = 100  # live connections at once; more are refused (each costs memory and a send per update)
DEFAULT_MAX_CLIENTS_PER_ADDRESS = 20  # live connections of one address without a login (or of one login): a visitor's tabs

_DURATION: dict[str, Any] = {"type": ["string", "number"], "description": "A duration: 10ms, 1s, 2min, or a number of seconds."}

HMI_SERVER: dict[str, Any] = {
    "description": "The web HMI (docs/hmi.md).",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no HMI (default true)."},
        "host": {"type": "string", "description": "Bind address (default 127.0.0.1: this computer only)."},
        "port": {"type": "integer", "minimum": 0, "maximum": 65535, "description": "TCP port (default 8080; 0 = any free port)."},
        "anonymous": {"enum": ["off", "viewer"], "description": "Visitors who have not logged in: refused, or read-only (default viewer on loopback, off elsewhere)."},
        "users_file": {"type": "string", "description": "Users and roles, relative to this file (default: the OPC UA users file, STATE_DIR/users.yaml)."},
        "tls": {
            "description": "HTTPS: true (a certificate made in STATE_DIR/hmi/tls on first start) or {certificate, private_key} (PEM files).",
            "type": ["boolean", "object"],
            "properties": {
                "certificate": {"type": "string", "description": "PEM certificate (chain), relative to this file."},
                "private_key": {"type": "string", "description": "PEM private key of the certificate."},
            },
            "required": ["certificate", "private_key"],
            "additionalProperties": False,
        },
        "max_update_rate": {"type": "number", "minimum": 0.2, "maximum": 100, "description": "Most live updates of each value per second sent to one browser (default 10)."},
        "heartbeat": {**_DURATION, "description": "Interval of the live channel's heartbeats (default 2s); a silent peer is dropped after 2.5 intervals."},
        "session_timeout": {**_DURATION, "description": "A login expires after this long without a request (default 8h)."},
        "max_clients": {"type": "integer", "minimum": 1, "maximum": 10000, "description": "Most live connections at once (default 100)."},
        "max_clients_per_address": {"type": "integer", "minimum": 1, "maximum": 10000,
                                    "description": "Most live connections of one address without a login, and of one login (default 20)."},
        "allowed_origins": {
            "type": "array",
            "items": {"type": "string"},
            "description": "Other origins allowed to open the live channel and write, e.g. https://scada.example.com behind a reverse proxy.",
        },
        "metrics": METRICS_SCHEMA,  # /metrics on this server (softplc/adapters/hmi/metrics_settings.py)
    },
    "additionalProperties": False,
}

# -- user views (`hmi: views:`) ---------------------------------------------------------------

EXPRESSION: dict[str, Any] = {"type": "string", "description": "A tag name, or an expression over tags (the language of --until), e.g. t01_iBL > 90."}
_SOURCE_KEYS: dict[str, Any] = {
    "tag": {"type": "string", "description": "The tag whose value drives this binding."},
    "expr": EXPRESSION,
}
COLOR: dict[str, Any] = {"type": "string", "description": "A CSS colour: #rgb, #rrggbb, a name such as red, or rgb(...)."}
NUMBER_PAIR: dict[str, Any] = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}


def _sourced(description: str, properties: dict[str, Any]) -> dict[str, Any]:
    """A binding written as an expression string, or a mapping with `tag:` or `expr:` and options."""
    return {
        "description": description,
        "type": ["string", "object"],
        "properties": {**_SOURCE_KEYS, **properties},
        "additionalProperties": False,
    }


BINDING: dict[str, Any] = {
    "description": "What drives the SVG element with this id.",
    "type": "object",
    "properties": {
        "text": _sourced("Show the value as the element's text.", {
            "decimals": {"type": "integer", "minimum": 0, "maximum": 10, "description": "Digits after the point (default: as the value comes)."},
            "unit": {"type": "string", "description": "Unit after the value (default: the tag's unit)."},
            "map": {"type": "object", "additionalProperties": {"type": "string"}, "description": "Value → text, e.g. {0: waiting, 1: to source}."},
        }),
        "fill": _sourced("Fill colour: on_color/off_color (by truth), or thresholds [[from, colour], ...].", {
            "on_color": COLOR, "off_color": COLOR,
            "thresholds": {"type": "array", "items": {"type": "array", "minItems": 2, "maxItems": 2}, "minItems": 1,
                           "description": "[[value, colour], ...]: the colour of the highest value not above the tag's."},
        }),
        "stroke": _sourced("Stroke colour, as fill.", {
            "on_color": COLOR, "off_color": COLOR,
            "thresholds": {"type": "array", "items": {"type": "array", "minItems": 2, "maxItems": 2}, "minItems": 1},
        }),
        "visible": _sourced("Show the element while this holds.", {}),
        "bar": _sourced("A <rect> whose length follows the value within a range.", {
            "min": {"type": "number", "description": "Value of an empty bar (default: the tag's min, else 0)."},
            "max": {"type": "number", "description": "Value of a full bar (default: the tag's max, else 100)."},
            "direction": {"enum": ["up", "down", "left", "right"], "description": "Where the bar grows (default up)."},
        }),
        "translate": {
            "description": "Move the element: SVG offset = offset + scale × value, per axis.",
            "type": "object",
            "properties": {
                "x": {"type": ["string", "object"], "properties": _SOURCE_KEYS, "additionalProperties": False},
                "y": {"type": ["string", "object"], "properties": _SOURCE_KEYS, "additionalProperties": False},
                "scale": {"type": ["number", "array"], "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
                          "description": "SVG units per value unit: one number, or [x, y] (negative y for a map's upward y)."},
                "offset": NUMBER_PAIR,
            },
            "additionalProperties": False,
        },
        "rotate": _sourced("Rotate the element by offset + scale × value degrees.", {
            "scale": {"type": "number", "description": "Degrees per value unit (default 1; -57.29578 for radians counter-clockwise on a map)."},
            "offset": {"type": "number"},
            "center": NUMBER_PAIR,
        }),
        "click": {
            "description": "On click: write a value (always after a confirmation), or open the write dialog of a tag.",
            "type": "object",
            "properties": {
                "tag": {"type": "string", "description": "The tag to write."},
                "write": {"type": ["boolean", "number", "string"], "description": "The value a click writes."},
                "dialog": {"type": "string", "description": "Open the write dialog of this tag instead."},
            },
            "additionalProperties": False,
        },
    },
    "additionalProperties": False,
    "minProperties": 1,
}

VIEW: dict[str, Any] = {
    "description": "A user mimic: an SVG drawing (e.g. from Inkscape) whose elements are bound to tags by id.",
    "type": "object",
    "properties": {
        "title": {"type": "string", "description": "Shown in the navigation (default: the view's name)."},
        "svg": {"type": "string", "description": "The SVG file, relative to this file."},
        "bindings": {"type": "object", "additionalProperties": BINDING, "description": "SVG element id → what drives it."},
    },
    "required": ["svg"],
    "additionalProperties": False,
}

HMI_SECTION: dict[str, Any] = {
    "description": "What the web HMI shows beyond the built-in pages (docs/hmi.md).",
    "type": "object",
    "properties": {
        "views": {"type": "object", "propertyNames": {"pattern": r"^[A-Za-z_][A-Za-z0-9_]*$"}, "additionalProperties": VIEW},
    },
    "additionalProperties": False,
}


@dataclass(frozen=True)
class HmiSettings:
    """Where and how the HMI serves; paths left None default into the state directory."""

    enabled: bool = True
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    anonymous: str | None = None  # "off" | "viewer"; None: viewer on loopback, off elsewhere
    users_file: Path | None = None  # None: STATE_DIR/users.yaml (the OPC UA users file)
    tls: bool = False
    certificate: Path | None = None  # with private_key: this certificate instead of a generated one
    private_key: Path | None = None
    max_update_rate: float = DEFAULT_UPDATE_RATE
    heartbeat: float = DEFAULT_HEARTBEAT
    session_timeout: float = DEFAULT_SESSION_TIMEOUT
    max_clients: int = DEFAULT_MAX_CLIENTS
    max_clients_per_address: int = DEFAULT_MAX_CLIENTS_PER_ADDRESS
    allowed_origins: tuple[str, ...] = ()
    open_browser: bool = False  # --hmi-open: open the overview in a browser once serving

    @classmethod
    def from_config(cls, config: PlantConfig) -> HmiSettings:
        """Settings from the (schema-checked) `servers.hmi` mapping; bad durations fall back to defaults (see hmi_problems)."""
        section = config.servers.get("hmi")
        section = section if isinstance(section, dict) else {}
        base = config.base_dir
        users = section.get("users_file")
        if users is None:  # one user store: the OPC UA server's file unless the HMI names its own
            opcua = config.servers.get("opcua")
            users = opcua.get("users_file") if isinstance(opcua, dict) else None
        tls = section.get("tls", False)
        certificate = private_key = None
        if isinstance(tls, dict):
            certificate, private_key = base / str(tls.get("certificate")), base / str(tls.get("private_key"))
        return cls(
            enabled=bool(section.get("enabled", True)),
            host=str(section.get("host", DEFAULT_HOST)),
            port=int(section.get("port", DEFAULT_PORT)),
            anonymous=section.get("anonymous"),
            users_file=base / str(users) if users is not None else None,
            tls=bool(tls),
            certificate=certificate,
            private_key=private_key,
            max_update_rate=float(section.get("max_update_rate", DEFAULT_UPDATE_RATE)),
            heartbeat=_seconds(section.get("heartbeat"), DEFAULT_HEARTBEAT),
            session_timeout=_seconds(section.get("session_timeout"), DEFAULT_SESSION_TIMEOUT),
            max_clients=int(section.get("max_clients", DEFAULT_MAX_CLIENTS)),
            max_clients_per_address=int(section.get("max_clients_per_address", DEFAULT_MAX_CLIENTS_PER_ADDRESS)),
            allowed_origins=tuple(str(origin).rstrip("/") for origin in section.get("allowed_origins", ())),
        )

    def override(self, **changes: Any) -> HmiSettings:
        """A copy with the given fields replaced (None values are ignored)."""
        return replace(self, **{key: value for key, value in changes.items() if value is not None})

    # -- derived ----------------------------------------------------------------------------

    @property
    def loopback(self) -> bool:
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False

    @property
    def anonymous_role(self) -> Role | None:
        """The role of a visitor who has not logged in (None: must log in)."""
        mode = self.anonymous if self.anonymous is not None else ("viewer" if self.loopback else "off")
        return Role.VIEWER if mode == "viewer" else None

    @property
    def scheme(self) -> str:
        return "https" if self.tls else "http"

    def users_path(self, state_dir: Path) -> Path:
        return self.users_file if self.users_file is not None else state_dir / "users.yaml"

    def tls_dir(self, state_dir: Path) -> Path:
        return state_dir / "hmi" / "tls"


def hmi_problems(config: PlantConfig) -> list[Problem]:
    """Located mistakes of `servers: hmi:` and `hmi:` that the schema cannot see."""
    from softplc.adapters.hmi.views import view_problems

    return [*settings_problems(config), *view_problems(config)]


def settings_problems(config: PlantConfig) -> list[Problem]:
    """Durations, the host's form and TLS files of `servers.hmi`."""
    from softplc.config.yamlsource import Location, Problem

    section = config.servers.get("hmi")
    if not isinstance(section, dict):
        return []

    def problem(key: tuple[Any, ...], message: str) -> Problem:
        path = ("servers", "hmi", *key)
        return config.source.problem(path, message) if config.source else Problem(Location(str(config.path), 1, 1), message)

    problems = []
    for key, least, most in (("heartbeat", 0.2, 60.0), ("session_timeout", 60.0, 30 * 86400.0)):
        if key not in section:
            continue
        try:
            seconds = parse_duration(section[key])
        except (TypeError, ValueError) as error:
            problems.append(problem((key,), f"bad {key} {section[key]!r}: {error}"))
            continue
        if not least <= seconds <= most:
            problems.append(problem((key,), f"{key} must be between {least:g} s and {most:g} s, not {seconds:g} s"))
    host = section.get("host")
    if isinstance(host, str) and not is_host(host):
        problems.append(problem(("host",), f"not an IP address or host name: {host!r}"))
    tls = section.get("tls")
    if isinstance(tls, dict):
        for key in ("certificate", "private_key"):
            value = tls.get(key)
            if isinstance(value, str) and not (config.base_dir / value).is_file():
                problems.append(problem(("tls", key), f"{key} file not found: {config.base_dir / value}"))
    for index, origin in enumerate(section.get("allowed_origins") or ()):
        if isinstance(origin, str) and not origin.startswith(("http://", "https://")):
            problems.append(problem(("allowed_origins", index), f"an origin looks like https://host[:port], not {origin!r}"))
    return [*problems, *metrics_problems(config)]


def _seconds(value: Any, default: float) -> float:
    if value is None:
        return default
    try:
        return parse_duration(value)
    except (TypeError, ValueError):
        return default
