"""The audit trail's part of tagdb.yaml: the optional `audit:` section (softplc/storage/audit/settings.py)."""

from __future__ import annotations

from softplc.config.schema import Section
from softplc.storage.audit.settings import AUDIT_SCHEMA, problems

SECTION = Section(path=("audit",), schema=AUDIT_SCHEMA, problems=problems)
