"""Every rule a write can break has its answer in every protocol: no refusal ends in a KeyError or a generic fault."""

from __future__ import annotations

import pytest

from softplc.core.tagdb import Rule


@pytest.mark.parametrize("rule", list(Rule), ids=lambda rule: rule.name)
def test_every_rule_has_an_opcua_status_a_modbus_exception_and_the_cli_reads_it_back(rule: Rule) -> None:
    from softplc.adapters.modbus.server import EXCEPTION_FOR_RULE
    from softplc.adapters.opcua.writes import _RULE_CODES
    from softplc.clients.tags.writing import _CODE_RULES

    assert rule in _RULE_CODES, f"OPC UA has no StatusCode for {rule}"
    assert rule in EXCEPTION_FOR_RULE, f"Modbus has no exception code for {rule}"
    if rule is not Rule.INVALID_REQUEST:  # a protocol's own refusal: the client shows the status as it is
        assert _CODE_RULES.get(_RULE_CODES[rule]) is rule, f"softplc write does not read {rule} back from its StatusCode"


def test_a_standby_is_busy_for_modbus_and_in_an_invalid_state_for_opcua() -> None:
    from asyncua import ua
    from pymodbus.constants import ExcCodes

    from softplc.adapters.modbus.server import EXCEPTION_FOR_RULE
    from softplc.adapters.opcua.writes import _RULE_CODES

    assert EXCEPTION_FOR_RULE[Rule.NOT_ACTIVE] is ExcCodes.DEVICE_BUSY
    assert _RULE_CODES[Rule.NOT_ACTIVE] == ua.StatusCodes.BadInvalidState
