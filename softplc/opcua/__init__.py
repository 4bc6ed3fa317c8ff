"""OPC UA server adapter: every tag of the plant, typed, validated, secured (see server.py)."""

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from softplc.opcua.address_space import tag_node_id
    from softplc.opcua.client import ClientCertificate, ensure_client_certificate, make_client
    from softplc.opcua.roles import Role
    from softplc.opcua.security import Pki
    from softplc.opcua.server import OpcUaServer
    from softplc.opcua.settings import DEFAULT_NAMESPACE, OpcUaSettings
    from softplc.opcua.users import UserStore
    from softplc.opcua.variants import variant_for

# Public names and their modules, imported on first use (PEP 562): `softplc --help` imports
# softplc.opcua.cli and must not load asyncua with it.
_MODULES = {
    "softplc.opcua.address_space": ("tag_node_id",),
    "softplc.opcua.client": ("ClientCertificate", "ensure_client_certificate", "make_client"),
    "softplc.opcua.roles": ("Role",),
    "softplc.opcua.security": ("Pki",),
    "softplc.opcua.server": ("OpcUaServer",),
    "softplc.opcua.settings": ("DEFAULT_NAMESPACE", "OpcUaSettings"),
    "softplc.opcua.users": ("UserStore",),
    "softplc.opcua.variants": ("variant_for",),
}
_EXPORTS = {name: module for module, names in _MODULES.items() for name in names}

__all__ = [
    "DEFAULT_NAMESPACE", "ClientCertificate", "OpcUaServer", "OpcUaSettings", "Pki", "Role", "UserStore",
    "ensure_client_certificate", "make_client", "tag_node_id", "variant_for",
]


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value  # the next lookup does not come here
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
