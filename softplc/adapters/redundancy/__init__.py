"""A hot-standby pair of runtimes under an etcd lease (docs/redundancy.md)."""
