"""Security: users and roles file, password hashes, login throttling, and the PKI (certificates, trust list)."""
