"""The `servers.opcua` section of tagdb.yaml: its schema and the checks a schema cannot make."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.adapters.opcua.settings import POLICIES, OpcUaSettings, SettingsError
from softplc.config.schema import Section

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no OPC UA server (default true)."},
        "endpoint": {"type": "string", "description": "opc.tcp://HOST:PORT/PATH (default opc.tcp://127.0.0.1:4840/softplc/; port 0 = any free port)."},
        "namespace": {"type": "string", "description": "Namespace URI of the tags (default urn:softplc:tags)."},
        "application_uri": {"type": "string", "description": "ApplicationUri of the server, also in its certificate (default urn:softplc:server)."},
        "security": {
            "type": "array",
            "minItems": 1,
            "items": {"enum": list(POLICIES)},
            "description": "Security policies offered (default: all three on a loopback endpoint, the two Basic256Sha256 modes elsewhere).",
        },
        "anonymous": {"enum": ["off", "viewer"], "description": "Anonymous sessions: refused, or read-only (default viewer on loopback, off elsewhere)."},
        "users_file": {"type": "string", "description": "Users, roles and password hashes, relative to this file (default STATE_DIR/users.yaml; softplc users ...)."},
        "pki_dir": {"type": "string", "description": "Server certificate and trusted/rejected client certificates (default STATE_DIR/pki)."},
        "certificate": {"type": "string", "description": "Use this server certificate (DER or PEM) instead of generating one; needs private_key."},
        "private_key": {"type": "string", "description": "Private key (PEM) of `certificate`."},
        "folder_size": {"type": "integer", "minimum": 10, "maximum": 10000, "description": "Most children per folder before it is split (default 100)."},
        "max_message_size": {"type": "integer", "minimum": 65536, "maximum": 268435456, "description": "Largest request in bytes, all chunks together (default 4194304); 64 KB before a session is activated."},
        "max_chunk_count": {"type": "integer", "minimum": 1, "maximum": 8192, "description": "Most chunks of one request (default 512)."},
        "max_connections_per_peer": {"type": "integer", "minimum": 1, "maximum": 1000, "description": "Most simultaneous connections from one IP address; more are refused (default 50)."},
    },
    "additionalProperties": False,
}


def problems(config: PlantConfig) -> list[Problem]:
    """What the schema cannot see in `servers.opcua`: the endpoint's form, a certificate without its key."""
    try:
        OpcUaSettings.from_section(config.section("servers", "opcua"), config.base_dir)
    except SettingsError as error:
        return [config.problem(("servers", "opcua", error.key), str(error))]
    return []


SECTION = Section(path=("servers", "opcua"), schema=SCHEMA, problems=problems)
