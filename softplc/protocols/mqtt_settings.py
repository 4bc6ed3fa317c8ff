"""The `mqtt:` section: the broker every MQTT user of the runtime connects to (VDA 5050, Sparkplug B).

    mqtt:
      url: mqtt://127.0.0.1:1883        # mqtts://HOST:8883 for TLS; the default is this computer, port 1883
      client_id: line1-softplc          # each user adds its own suffix (…-vda5050, …-sparkplug); default softplc-PLANT
      username: softplc                 # optional
      password_file: mqtt.password      # the password's first line; relative to the plant file
      tls: {ca_file: ca.pem, cert_file: client.pem, key_file: client.key, verify: true}
      keepalive: 15s
      protocol: "5"                     # "3.1.1" or "5" (default 5; 3.1.1 with embedded)
      embedded: true                    # the runtime starts a broker itself at the url (amqtt): a laptop demo,
                                        # NOT for production (no TLS, no users, no ACLs; loopback only)

Each user opens its own connection with these settings (each has its own last will). Nothing
here imports an MQTT library; `softplc.protocols.mqtt` makes the connection.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import urlparse

from softplc.util.addresses import is_host
from softplc.util.durations import parse_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SECTION = "mqtt"
DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}
PROTOCOLS = ("3.1.1", "5")

SCHEMA: dict[str, Any] = {
    "description": "The MQTT broker of every MQTT user of the runtime (VDA 5050 vehicles, Sparkplug B): docs/mqtt.md.",
    "type": "object",
    "properties": {
        "url": {"type": "string", "description": "mqtt://HOST:PORT, or mqtts://HOST:PORT for TLS (default mqtt://127.0.0.1:1883)."},
        "client_id": {"type": "string", "description": "Client id prefix; each user adds its own suffix (default softplc-PLANT)."},
        "username": {"type": "string"},
        "password_file": {"type": "string", "description": "A file whose first line is the password (relative to the plant file)."},
        "tls": {
            "type": "object",
            "properties": {
                "ca_file": {"type": "string", "description": "CA certificates (PEM) the broker's certificate must chain to."},
                "cert_file": {"type": "string", "description": "Client certificate (PEM), for brokers that require one."},
                "key_file": {"type": "string", "description": "The client certificate's private key (PEM)."},
                "verify": {"type": "boolean", "description": "Check the broker's certificate and name (default true)."},
            },
            "additionalProperties": False,
        },
        "keepalive": {"type": ["string", "number"], "description": "Keep-alive interval, e.g. 15s (default 15s)."},
        "protocol": {"enum": list(PROTOCOLS), "description": "MQTT protocol version (default 5; 3.1.1 with embedded)."},
        "embedded": {"type": "boolean", "description": "Start a broker (amqtt) inside the runtime at the url: for a laptop "
                     "demo, NOT for production (no TLS, no users, no ACLs; loopback only). Default false."},
    },
    "additionalProperties": False,
}


@dataclass(frozen=True)
class TlsSettings:
    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None
    verify: bool = True


@dataclass(frozen=True)
class MqttSettings:
    """Resolved `mqtt:` (paths absolute)."""

    host: str = "127.0.0.1"
    port: int = 1883
    client_id: str = "softplc"
    username: str | None = None
    password_file: Path | None = None
    tls: TlsSettings | None = None
    keepalive: float = 15.0
    protocol: str = "5"
    embedded: bool = False  # the runtime runs the broker itself (softplc/adapters/mqtt/broker.py): demos only

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"

    def password(self) -> str | None:
        """The password file's first line (read when connecting, so a changed file takes effect on reconnect)."""
        if self.password_file is None:
            return None
        lines = self.password_file.read_text(encoding="utf-8").splitlines()
        return lines[0] if lines else ""

    @classmethod
    def from_config(cls, config: PlantConfig) -> MqttSettings:
        """`mqtt:` of a checked configuration (defaults when it is missing)."""
        section = config.raw.get(SECTION)
        section = section if isinstance(section, dict) else {}
        url = urlparse(str(section.get("url", "mqtt://127.0.0.1:1883")))
        tls_section = section.get("tls")
        tls = None
        if url.scheme == "mqtts" or isinstance(tls_section, dict):
            tls_section = tls_section if isinstance(tls_section, dict) else {}

            def path(key: str) -> Path | None:
                return config.base_dir / tls_section[key] if tls_section.get(key) else None

            tls = TlsSettings(path("ca_file"), path("cert_file"), path("key_file"), bool(tls_section.get("verify", True)))
        password_file = section.get("password_file")
        return cls(
            host=url.hostname or "127.0.0.1",
            port=url.port or DEFAULT_PORTS.get(url.scheme, 1883),
            client_id=str(section.get("client_id") or f"softplc-{config.name}"),
            username=section.get("username"),
            password_file=config.base_dir / password_file if password_file else None,
            tls=tls,
            keepalive=parse_duration(section.get("keepalive", "15s")),
            protocol=str(section.get("protocol", "3.1.1" if section.get("embedded") else "5")),
            embedded=bool(section.get("embedded", False)),
        )


def problems(config: PlantConfig) -> list[Problem]:
    """What the schema cannot say of `mqtt:`: the url's form, durations, files that must exist."""
    section = config.raw.get(SECTION)
    if not isinstance(section, dict):
        return []
    found: list[Problem] = []

    def at(key: tuple[str, ...], message: str) -> None:
        found.append(config.problem((SECTION, *key), message))

    if "url" in section:
        url = urlparse(str(section["url"]))
        if url.scheme not in DEFAULT_PORTS:
            at(("url",), f"url must start with mqtt:// or mqtts://, not {section['url']!r}")
        elif not url.hostname or not is_host(url.hostname):
            at(("url",), f"url {section['url']!r} names no broker host")
        else:
            try:
                url.port
            except ValueError:
                at(("url",), f"url {section['url']!r} has a bad port (1..65535)")
    if "keepalive" in section:
        try:
            seconds = parse_duration(section["keepalive"])
        except (TypeError, ValueError) as error:
            at(("keepalive",), f"bad keepalive {section['keepalive']!r}: {error}")
        else:
            if not 1 <= seconds <= 65535:
                at(("keepalive",), f"keepalive must be between 1 s and 65535 s, not {seconds:g} s")
    if section.get("embedded"):
        url = urlparse(str(section.get("url", "mqtt://127.0.0.1:1883")))
        if url.scheme == "mqtts" or section.get("tls") is not None:
            at(("embedded",), "the embedded broker has no TLS: use mqtt:// and no tls:, or a real broker (docs/vda5050.md)")
        elif url.hostname not in ("127.0.0.1", "localhost", "::1"):
            at(("embedded",), f"the embedded broker serves this computer only (loopback), not {url.hostname}: it has no users "
                              "or ACLs; run mosquitto for a network (docs/vda5050.md)")
        if str(section.get("protocol", "3.1.1")) == "5":
            at(("protocol",), "the embedded broker (amqtt) speaks MQTT 3.1.1 only: protocol: \"3.1.1\"")
    files = [(("password_file",), section.get("password_file"))]
    tls = section.get("tls")
    if isinstance(tls, dict):
        files += [(("tls", key), tls.get(key)) for key in ("ca_file", "cert_file", "key_file")]
        if bool(tls.get("cert_file")) != bool(tls.get("key_file")):
            at(("tls",), "cert_file and key_file go together")
    for key, name in files:
        if name and not (config.base_dir / str(name)).is_file():
            at(key, f"file not found: {config.base_dir / str(name)}")
    return found
