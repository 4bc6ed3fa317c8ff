"""The audit trail: every client write and every command, accepted or refused, with who, from where, and when.

Modules: `settings` (the `audit:` section) and `section` (its registry entry), `entry` (one
entry and its row), `store` (time-partitioned tables, the writer-side sink, retention),
`recorder` (the adapter listening on `db.on_write` and `commands.on_call`), `queries`
(searching the store), `commands` (`audit.query` for the HMI and the remote CLI), `cli`
(`softplc audit`). See docs/operations.md, "Audit trail". The core never imports this package.
"""

from softplc.util.lazy import lazy_exports

# Imported on first use: the section module is loaded with every configuration, so this
# package must stay light.
__getattr__, __dir__ = lazy_exports(__name__, {
    "softplc.storage.audit.settings": ("AuditSettings",),
    "softplc.storage.audit.entry": ("AuditEntry",),
    "softplc.storage.audit.queries": ("AuditQuery", "search", "write_csv"),
    "softplc.adapters.audit.recorder": ("AuditRecorder",),
})
