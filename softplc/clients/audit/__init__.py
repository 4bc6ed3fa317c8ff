"""`softplc audit`: the audit trail, from the plant's store or over OPC UA."""
