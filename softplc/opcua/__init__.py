"""OPC UA server adapter: every tag of the plant, typed, validated, secured (see server.py)."""

from softplc.opcua.address_space import tag_node_id
from softplc.opcua.client import ClientCertificate, ensure_client_certificate, make_client
from softplc.opcua.roles import Role
from softplc.opcua.security import Pki
from softplc.opcua.server import OpcUaServer
from softplc.opcua.settings import DEFAULT_NAMESPACE, OpcUaSettings
from softplc.opcua.users import UserStore
from softplc.opcua.variants import variant_for

__all__ = [
    "DEFAULT_NAMESPACE", "ClientCertificate", "OpcUaServer", "OpcUaSettings", "Pki", "Role", "UserStore",
    "ensure_client_certificate", "make_client", "tag_node_id", "variant_for",
]
