"""The JSON Schema of `tagdb.yaml` (printed by `softplc schema`, used by `softplc check`).

Structure is checked here; what a schema cannot say (a binding to a missing tag, an initial
value outside its type, a program class that does not exist) is checked in `config.py`.
"""

from __future__ import annotations

from typing import Any

from softplc.datatypes import TYPE_NAMES
from softplc.durations import DURATION_REGEX
from softplc.hmi.settings import HMI_SECTION, HMI_SERVER  # HMI branch: plain schema data, onto the config registry at merge

NAME_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"
NAME_RULE = "letters, digits and _, not starting with a digit"

DURATION: dict[str, Any] = {
    "description": "A duration: 10ms, 1s, 2min, 250us, or a number of seconds.",
    "type": ["string", "number"],
}

MODBUS_TAG: dict[str, Any] = {
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

TAG: dict[str, Any] = {
    "description": "A tag: a typed value with quality and timestamp.",
    "type": "object",
    "properties": {
        "type": {"enum": list(TYPE_NAMES), "description": "The tag's data type."},
        "initial": {"type": ["boolean", "number", "string"], "description": "Value at start (default 0, false or '')."},
        "unit": {"type": "string", "description": "Engineering unit, e.g. m, %, items/min."},
        "description": {"type": "string"},
        "access": {"enum": ["rw", "ro"], "description": "ro: read-only for clients (programs may write)."},
        "min": {"type": "number", "description": "Lowest value a write may set."},
        "max": {"type": "number", "description": "Highest value a write may set."},
        "retain": {"type": "boolean", "description": "Keep the value across restarts (stored in SQLite)."},
        "group": {"type": "string", "description": "Folder path for browsing, e.g. Plant/Handshake."},
        "modbus": MODBUS_TAG,
    },
    "required": ["type"],
    "additionalProperties": False,
}

TAGS: dict[str, Any] = {
    "type": "object",
    "propertyNames": {"pattern": NAME_PATTERN},
    "additionalProperties": TAG,
}

TEMPLATE: dict[str, Any] = {
    "description": "A tag set declared once and instantiated per robot or task: tag NAME becomes INSTANCE_NAME.",
    "type": "object",
    "properties": {
        "description": {"type": "string"},
        "group": {"type": "string", "description": "Folder of the instances, e.g. Robots."},
        "instances": {
            "type": "array",
            "items": {"type": "string", "pattern": NAME_PATTERN},
            "description": "Instance names, e.g. [r01, r02, r03].",
        },
        "count": {"type": "integer", "minimum": 1, "maximum": 9999, "description": "Number of instances PREFIX01..PREFIXnn."},
        "prefix": {"type": "string", "pattern": NAME_PATTERN, "description": "Instance name prefix used with count."},
        "instances_from": {
            "description": "Instance names from the `id` of each item of a YAML list in another file "
            "(e.g. robots/robots.yaml), optionally with initial values taken from the items.",
            "type": ["string", "object"],
            "properties": {
                "file": {"type": "string", "description": "YAML file, relative to this one."},
                "key": {"type": "string", "description": "The top-level key of the list (default: the file's only list)."},
                "initial": {
                    "type": "object",
                    "additionalProperties": {"type": "string"},
                    "description": "TAG: dotted.key of an item, e.g. {xpos: start.x}; items without the key keep the tag's initial.",
                },
            },
            "required": ["file"],
            "additionalProperties": False,
        },
        "tags": TAGS,
        "initial": {
            "type": "object",
            "description": "Per-instance initial values: {INSTANCE: {TAG: value}}.",
            "additionalProperties": {"type": "object", "additionalProperties": {"type": ["boolean", "number", "string"]}},
        },
    },
    "required": ["tags"],
    "additionalProperties": False,
}

PROGRAM: dict[str, Any] = {
    "description": "A program instance: a Program class and the binding of its variables to tags.",
    "type": "object",
    "properties": {
        "name": {"type": "string", "description": "Instance name; may use {INSTANCE} with for_each."},
        "program": {"type": "string", "description": "module:Class or module.Class, or path/to/file.py:Class."},
        "for_each": {"type": "string", "description": "A template name: one instance per template instance."},
        "bind": {
            "type": "object",
            "additionalProperties": {"type": ["string", "array"], "items": {"type": "string"}},
            "description": "Variable → tag name (or list of tag names).",
        },
        "params": {"type": "object", "description": "Constant parameters of the program."},
        "on_fault": {"enum": ["stop", "restart"], "description": "stop: stay FAULTED; restart: restart after restart_delay."},
        "restart_delay": DURATION,
        "max_restarts": {"type": "integer", "minimum": 0},
        "enabled": {"type": "boolean"},
    },
    "required": ["name", "program"],
    "additionalProperties": False,
}

TASK: dict[str, Any] = {
    "description": "A cyclic task: its programs run every `interval`.",
    "type": "object",
    "properties": {
        "interval": DURATION,
        "priority": {"type": "integer", "minimum": 0, "maximum": 31, "description": "0 is the highest priority."},
        "watchdog": DURATION,
        "programs": {"type": "array", "items": PROGRAM},
    },
    "required": ["interval"],
    "additionalProperties": False,
}

OPCUA_SERVER: dict[str, Any] = {
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no OPC UA server (default true)."},
        "endpoint": {"type": "string", "description": "opc.tcp://HOST:PORT/PATH (default opc.tcp://127.0.0.1:4840/softplc/; port 0 = any free port)."},
        "namespace": {"type": "string", "description": "Namespace URI of the tags (default urn:softplc:tags)."},
        "application_uri": {"type": "string", "description": "ApplicationUri of the server, also in its certificate (default urn:softplc:server)."},
        "security": {
            "type": "array",
            "minItems": 1,
            "items": {"enum": ["None", "Basic256Sha256_Sign", "Basic256Sha256_SignAndEncrypt"]},
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

MODBUS_SERVER: dict[str, Any] = {
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean"},
        "host": {"type": "string"},
        "port": {"type": "integer", "minimum": 0, "maximum": 65535},
        "unit_id": {"type": "integer", "minimum": 0, "maximum": 247},
        "word_order": {"enum": ["big", "little"], "description": "Order of the 16-bit words of 32/64-bit values."},
        "string_words": {"type": "integer", "minimum": 1, "maximum": 123, "description": "Registers per string tag (default 16)."},
        "system_tags": {"type": "boolean", "description": "Serve the _sys. tags (default true)."},
        "system_base": {"type": "integer", "minimum": 0, "maximum": 65535, "description": "First address of the _sys. tag block in each table (default 60000)."},
        "max_connections": {"type": "integer", "minimum": 1, "maximum": 4096, "description": "Most simultaneous client connections; more are refused (default 64)."},
        "idle_timeout": {**DURATION, "description": "Close a connection that sent nothing for this long; 0 = never (default 60s)."},
    },
    "additionalProperties": False,
}

FLEET: dict[str, Any] = {
    "description": "Mobile robots driven by the runtime (softplc.fleet; docs/robots.md).",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no robot is driven (default true)."},
        "robots": {"type": "string", "description": "Robots file, relative to this one (default robots/robots.yaml)."},
        "tasks": {"type": "string", "description": "Tasks file (default robots/tasks.yaml)."},
        "map": {"type": "string", "description": "Occupancy map YAML, ROS map_server format (default robots/maps/factory.yaml)."},
        "template": {"type": "string", "pattern": NAME_PATTERN, "description": "Template whose instances are the robots' tags (default robot)."},
        "cycle": DURATION,
        "max_linear_speed": {"type": "number", "exclusiveMinimum": 0, "description": "Floor speed limit, m/s (default 0.2)."},
        "max_angular_speed": {"type": "number", "exclusiveMinimum": 0, "description": "Floor turn-rate limit, rad/s (default 0.4)."},
        "planning_resolution": {"type": "number", "exclusiveMinimum": 0, "description": "Cell size of the A* grid, m (default 0.1)."},
        "goal_tolerance": {"type": "number", "exclusiveMinimum": 0, "description": "Goal reached within this distance, m (default 0.5)."},
        "heartbeat_timeout": DURATION,
    },
    "additionalProperties": False,
}

CONFIG_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://softplc.dev/schema/tagdb.json",
    "title": "softplc plant configuration (tagdb.yaml)",
    "type": "object",
    "properties": {
        "version": {"const": 1, "description": "Format version; 1."},
        "plant": {
            "type": "object",
            "properties": {"name": {"type": "string"}, "description": {"type": "string"}},
            "additionalProperties": False,
        },
        "templates": {"type": "object", "propertyNames": {"pattern": NAME_PATTERN}, "additionalProperties": TEMPLATE},
        "tags": TAGS,
        "tasks": {"type": "object", "propertyNames": {"pattern": NAME_PATTERN}, "additionalProperties": TASK},
        "servers": {
            "type": "object",
            "properties": {"opcua": OPCUA_SERVER, "modbus": MODBUS_SERVER, "hmi": HMI_SERVER},
            "additionalProperties": False,
        },
        "fleet": FLEET,
        "hmi": HMI_SECTION,
        "runtime": {
            "type": "object",
            "properties": {
                "state_dir": {"type": "string", "description": "Where retained values, certificates etc. live (default .softplc next to this file)."},
                "stall_after": DURATION,
            },
            "additionalProperties": False,
        },
    },
    "additionalProperties": False,
}


# For editors: durations are also checked for their form (the runtime's own check says more:
# `softplc check` reports "bad interval '10 parsecs': write a duration such as 10ms...").
STRICT_DURATION: dict[str, Any] = {
    "description": DURATION["description"],
    "anyOf": [
        {"type": "string", "pattern": DURATION_REGEX},
        {"type": "number", "exclusiveMinimum": 0},
    ],
}


def editor_schema() -> dict[str, Any]:
    """The schema `softplc schema` prints: CONFIG_SCHEMA with durations checked for their form too."""

    def strict(node: Any) -> Any:
        if node is DURATION:
            return STRICT_DURATION
        if isinstance(node, dict):
            return {key: strict(value) for key, value in node.items()}
        if isinstance(node, list):
            return [strict(item) for item in node]
        return node

    return strict(CONFIG_SCHEMA)
