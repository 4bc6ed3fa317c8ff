"""Names the OPC UA server and its clients agree on: the tags' namespace and the commands door."""

DEFAULT_NAMESPACE = "urn:softplc:tags"  # the namespace URI of every tag node (ns=2 on a softplc server)
COMMANDS_OBJECT = "Commands"  # Objects/Commands: the door to the plant's commands (Call, List)
