"""Every refusal rule of the tag database (`softplc.core.tagdb.Rule`) has a deliberate answer in every
protocol that maps rules: a rule added to the core without its protocol answers fails here, not
as a KeyError (and a Modbus exception 04 with a traceback) the first time a client meets it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from asyncua import ua
from conftest import REPO

from softplc.adapters.modbus.server import EXCEPTION_FOR_RULE
from softplc.adapters.opcua.writes import _RULE_CODES as OPCUA_STATUS_FOR_RULE
from softplc.clients.tags import writing as live_writing
from softplc.core.tagdb import Rule

# Tables keyed by Rule that are partial on purpose, with why.
PARTIAL_ON_PURPOSE = {
    ("softplc/clients/tags/writing.py", "_ROLE_FOR_RULE"): "which role makes the runtime's own message for a rule; others need none",
}


@pytest.mark.parametrize("rule", list(Rule), ids=lambda rule: rule.name)
def test_every_rule_has_a_modbus_exception_code(rule: Rule) -> None:
    assert rule in EXCEPTION_FOR_RULE, f"Modbus: no exception code for {rule} (softplc/adapters/modbus/server.py EXCEPTION_FOR_RULE, docs/modbus.md)"


@pytest.mark.parametrize("rule", list(Rule), ids=lambda rule: rule.name)
def test_every_rule_has_an_opcua_status_the_cli_reads_back_as_the_same_rule(rule: Rule) -> None:
    assert rule in OPCUA_STATUS_FOR_RULE, f"OPC UA: no status code for {rule} (softplc/adapters/opcua/writes.py, docs/opcua.md)"
    code = OPCUA_STATUS_FOR_RULE[rule]
    assert not ua.StatusCode(code).is_good()
    # softplc write reports the rule from the status code it gets back (softplc/clients/tags/writing.py).
    assert live_writing._CODE_RULES.get(code, Rule.INVALID_REQUEST) is rule


@pytest.mark.parametrize("rule", list(Rule), ids=lambda rule: rule.name)
def test_every_rule_reads_as_words_in_the_hmi_and_the_audit_trail(rule: Rule) -> None:
    # The HMI answers a refused item with HTTP 422 and {"rule": rule.value, "detail": ...}, and the
    # audit trail stores rule.value: every rule needs a short text of its own that maps back.
    assert rule.value and rule.value == rule.value.strip().lower()
    assert Rule(rule.value) is rule


def _rule_keyed_tables() -> list[tuple[str, str, set[str]]]:
    """(file, name, rule names) of every module-level dict literal in softplc/ keyed by Rule members."""
    tables = []
    for path in sorted((REPO / "softplc").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in tree.body:
            if not isinstance(node, (ast.Assign, ast.AnnAssign)) or not isinstance(node.value, ast.Dict):
                continue
            keys = node.value.keys
            if not keys or not all(isinstance(key, ast.Attribute) and isinstance(key.value, ast.Name) and key.value.id == "Rule" for key in keys):
                continue
            target = node.targets[0] if isinstance(node, ast.Assign) else node.target
            assert isinstance(target, ast.Name)
            tables.append((str(Path(path).relative_to(REPO)), target.id, {key.attr for key in keys}))  # type: ignore[union-attr]
    return tables


def test_every_table_keyed_by_rule_covers_every_rule() -> None:
    tables = _rule_keyed_tables()
    names = {(file, name) for file, name, _ in tables}
    assert ("softplc/adapters/modbus/server.py", "EXCEPTION_FOR_RULE") in names and ("softplc/adapters/opcua/writes.py", "_RULE_CODES") in names
    missing = {
        f"{file} {name}": sorted(rule.name for rule in Rule if rule.name not in keys)
        for file, name, keys in tables
        if (file, name) not in PARTIAL_ON_PURPOSE and len(keys) < len(Rule)
    }
    assert not missing, f"tables that map refusal rules but miss some: {missing}"


def test_a_standby_is_busy_for_modbus_and_in_an_invalid_state_for_opcua() -> None:
    # A redundant pair's standby (docs/redundancy.md): "busy, retry later" — the client should write to the active.
    from pymodbus.constants import ExcCodes

    assert EXCEPTION_FOR_RULE[Rule.NOT_ACTIVE] is ExcCodes.DEVICE_BUSY
    assert OPCUA_STATUS_FOR_RULE[Rule.NOT_ACTIVE] == ua.StatusCodes.BadInvalidState
