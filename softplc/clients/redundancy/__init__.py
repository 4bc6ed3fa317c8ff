"""`softplc redundancy`: the pair's certificates and its status, seen from outside the runtime."""
