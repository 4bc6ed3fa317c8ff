"""OPC UA server adapter: every tag of the plant, typed, validated, secured (see server.py)."""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.adapters.opcua.address_space import tag_node_id
    from softplc.adapters.opcua.server import OpcUaServer
    from softplc.adapters.opcua.settings import DEFAULT_NAMESPACE, OpcUaSettings
    from softplc.core.roles import Role
    from softplc.protocols.opcua_client import ClientCertificate, ensure_client_certificate, make_client
    from softplc.protocols.opcua_variants import variant_for
    from softplc.security.certificates import Pki
    from softplc.security.users import UserStore

# Public names and their modules, imported on first use (PEP 562): `softplc --help` imports
# softplc.adapters.opcua.cli and must not load asyncua with it.
_MODULES = {
    "softplc.adapters.opcua.address_space": ("tag_node_id",),
    "softplc.protocols.opcua_client": ("ClientCertificate", "ensure_client_certificate", "make_client"),
    "softplc.core.roles": ("Role",),
    "softplc.security.certificates": ("Pki",),
    "softplc.adapters.opcua.server": ("OpcUaServer",),
    "softplc.adapters.opcua.settings": ("DEFAULT_NAMESPACE", "OpcUaSettings"),
    "softplc.security.users": ("UserStore",),
    "softplc.protocols.opcua_variants": ("variant_for",),
}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = [
    "DEFAULT_NAMESPACE", "ClientCertificate", "OpcUaServer", "OpcUaSettings", "Pki", "Role", "UserStore",
    "ensure_client_certificate", "make_client", "tag_node_id", "variant_for",
]
