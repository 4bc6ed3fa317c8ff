"""Adapters around the core: each folder serves the plant to one kind of peer (docs/architecture.md)."""
