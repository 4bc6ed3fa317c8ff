"""An audit entry for a write from every source and for every kind of action, with who, from where, old, new and the rule.

One plant as `softplc run` builds it (audit trail, alarms, OPC UA, Modbus, the HMI; a 10 ms task),
real clients over loopback: asyncua, pymodbus, aiohttp on the HMI's JSON API, the live CLI
(`softplc write`, `softplc force` in their own processes), and the OPC UA door to the commands
(program control, online change, alarm acknowledgement, reset faults). The entries are read back
from the store.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import aiohttp
from asyncua import ua
from pymodbus.client import AsyncModbusTcpClient

from tests.audit_support import (
    PASSWORDS,
    adapter,
    call_door,
    entries,
    local_address,
    opcua_client,
    running,
    softplc,
    wait_until,
)


def row(entry: Any) -> tuple[Any, ...]:
    return (entry.kind, entry.source, entry.user, entry.role, entry.name, entry.tag, entry.old, entry.new, entry.accepted, entry.rule)


async def test_every_source_and_action_is_audited_with_who_old_new_and_rule(tmp_path: Path) -> None:
    async with running(tmp_path) as runtime:
        db = runtime.db
        endpoint = adapter(runtime, "opcua").endpoint
        modbus_map = adapter(runtime, "modbus").map.by_tag
        async with opcua_client(runtime, "operator") as operator, opcua_client(runtime, "engineer") as engineer, opcua_client(runtime) as anonymous:
            ns = await operator.get_namespace_index("urn:softplc:tags")

            async def write(client: Any, **values: Any) -> list[str]:
                nodes = [client.get_node(ua.NodeId(name, ns)) for name in values]
                data = [value if isinstance(value, ua.DataValue) else ua.DataValue(ua.Variant(*value)) for value in values.values()]
                return [status.name for status in await client.write_values(nodes, data, raise_on_partial_error=False)]

            # OPC UA: accepted, refused by range and by access, by role, and by the protocol (a client's quality)
            assert await write(operator, level=(42.5, ua.VariantType.Float)) == ["Good"]
            await wait_until(lambda: db.value("level") == 42.5)
            assert await write(operator, setpoint=(500, ua.VariantType.Int16), count=(3, ua.VariantType.UInt32)) == ["BadOutOfRange", "BadNotWritable"]
            assert await write(anonymous, setpoint=(1, ua.VariantType.Int16)) == ["BadUserAccessDenied"]
            bad = ua.DataValue(ua.Variant(1.0, ua.VariantType.Float), StatusCode=ua.StatusCode(ua.StatusCodes.Bad))
            assert await write(operator, level=bad) == ["BadWriteNotSupported"]
            # Modbus: accepted, refused by range
            modbus = AsyncModbusTcpClient("127.0.0.1", port=adapter(runtime, "modbus").port, timeout=2, retries=0)
            await modbus.connect()
            try:
                assert not (await modbus.write_register(modbus_map["setpoint"].address, 7)).isError()
                await wait_until(lambda: db.value("setpoint") == 7)
                assert (await modbus.write_register(modbus_map["setpoint"].address, 200)).isError()
                modbus_peer = local_address(modbus.ctx.transport)
            finally:
                modbus.close()
            # the HMI's JSON API: logged in, and not
            hmi = adapter(runtime, "hmi").url
            async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as browser:
                async with browser.post(hmi + "api/login", json={"user": "operator", "password": PASSWORDS["operator"]}) as response:
                    csrf = (await response.json())["csrf"]
                async with browser.post(hmi + "api/write", json={"tag": "setpoint", "value": 9}, headers={"X-CSRF-Token": csrf}) as response:
                    assert response.status == 200, await response.text()
            await wait_until(lambda: db.value("setpoint") == 9)
            async with aiohttp.ClientSession() as stranger:
                async with stranger.post(hmi + "api/write", json={"tag": "setpoint", "value": 66}) as response:
                    assert response.status == 403
            # the live CLI (an OPC UA client in its own process)
            code, _, err = await softplc("write", "setpoint=12", "--user", "operator", "--endpoint", endpoint, home=tmp_path, password=PASSWORDS["operator"])
            assert code == 0, err
            await wait_until(lambda: db.value("setpoint") == 12)
            # an alarm, acknowledged through the commands door
            assert await write(operator, level=(95.0, ua.VariantType.Float)) == ["Good"]
            await wait_until(lambda: db.value("_sys.alarms.unacknowledged") == 1)
            assert (await call_door(operator, "alarms.acknowledge", {"alarm": "level_hi"}))["ok"]
            # forcing from the CLI: an engineer may, an operator may not
            code, _, err = await softplc("force", "level=55", "--user", "engineer", "--endpoint", endpoint, home=tmp_path, password=PASSWORDS["engineer"])
            assert code == 0, err
            await wait_until(lambda: db["level"].forced)
            code, _, err = await softplc("force", "level=1", "--user", "operator", "--endpoint", endpoint, home=tmp_path, password=PASSWORDS["operator"])
            assert code == 4, err
            # program control and online change (engineers), reset faults (operators)
            assert (await call_door(engineer, "programs.stop", {"program": "ticker"}))["ok"]
            assert (await call_door(engineer, "programs.start", {"program": "ticker"}))["ok"]
            assert not (await call_door(engineer, "programs.stop", {"program": "nope"}))["ok"]
            assert (await call_door(engineer, "programs.apply", {"check": True}))["ok"]
            assert await call_door(operator, "programs.apply", {}) == "BadUserAccessDenied"
            assert (await call_door(operator, "runtime.reset_faults", {}))["ok"]
            assert await call_door(anonymous, "runtime.reset_faults", {}) == "BadUserAccessDenied"
            peers = {name: local_address(client.uaclient.protocol.transport) for name, client in
                     (("operator", operator), ("engineer", engineer), ("anonymous", anonymous))}
        found = await entries(runtime)

    assert [row(entry) for entry in found] == [
        ("write", "opcua", "operator", "operator", "level", "level", 0.0, 42.5, True, ""),
        # one Write of two items: the one the protocol's access check refuses is reported first
        ("write", "opcua", "operator", "operator", "count", "count", found[1].old, 3, False, "read-only"),
        ("write", "opcua", "operator", "operator", "setpoint", "setpoint", 0, 500, False, "out of range"),
        ("write", "opcua", "anonymous", "viewer", "setpoint", "setpoint", 0, 1, False, "access denied"),
        ("write", "opcua", "operator", "operator", "level", "level", 42.5, 1.0, False, "invalid request"),
        ("write", "modbus", "", "operator", "setpoint", "setpoint", 0, 7, True, ""),
        ("write", "modbus", "", "operator", "setpoint", "setpoint", 7, 200, False, "out of range"),
        ("write", "hmi", "operator", "operator", "setpoint", "setpoint", 7, 9, True, ""),
        # not logged in: no user, a viewer
        ("write", "hmi", "", "viewer", "setpoint", "setpoint", 9, 66, False, "access denied"),
        ("write", "opcua", "operator", "operator", "setpoint", "setpoint", 9, 12, True, ""),
        ("write", "opcua", "operator", "operator", "level", "level", 42.5, 95.0, True, ""),
        ("command", "opcua", "operator", "operator", "alarms.acknowledge", "", None, None, True, ""),
        ("command", "opcua", "engineer", "engineer", "tags.force", "level", 95.0, 55.0, True, ""),
        ("command", "opcua", "operator", "operator", "tags.force", "level", 55.0, 1.0, False, "access denied"),
        ("command", "opcua", "engineer", "engineer", "programs.stop", "", None, None, True, ""),
        ("command", "opcua", "engineer", "engineer", "programs.start", "", None, None, True, ""),
        ("command", "opcua", "engineer", "engineer", "programs.stop", "", None, None, False, "refused"),
        ("command", "opcua", "engineer", "engineer", "programs.apply", "", None, None, True, ""),
        ("command", "opcua", "operator", "operator", "programs.apply", "", None, None, False, "access denied"),
        ("command", "opcua", "operator", "operator", "runtime.reset_faults", "", None, None, True, ""),
        ("command", "opcua", "anonymous", "viewer", "runtime.reset_faults", "", None, None, False, "access denied"),
    ]
    assert isinstance(found[1].old, int)
    # Who and from where: OPC UA and HMI writes carry the client's address, Modbus writes and the
    # commands door its address and port (each client's own).
    assert {entry.peer for entry in found[:5] + found[7:11]} == {"127.0.0.1"}
    assert [entry.peer for entry in found[5:7]] == [modbus_peer] * 2
    assert found[11].peer == peers["operator"] and found[14].peer == peers["engineer"] and found[20].peer == peers["anonymous"]
    cli_peers = [found[12].peer, found[13].peer]  # the CLI's processes: their own connections
    assert all(peer.startswith("127.0.0.1:") and peer not in peers.values() for peer in cli_peers), cli_peers
    # What each refusal says, in the runtime's words; what each command was given and did.
    assert found[1].detail == "the tag is read-only for clients" and found[2].detail == "500 is above the maximum 100"
    assert found[3].detail == "role viewer may not write" and found[4].detail == "clients cannot write a tag's quality"
    assert found[8].detail == "log in to write"
    assert found[11].arguments == {"alarm": "level_hi"} and found[11].detail == "acknowledged level_hi (now acknowledged)"
    assert found[12].arguments == {"tag": "level", "value": "55"} and found[12].detail == "level forced to 55.0 from the next cycle"
    assert found[13].detail == "role operator may not force tags"
    assert found[16].detail.startswith("no program 'nope'"), found[16].detail
    assert found[17].arguments == {"check": True} and found[17].detail.startswith("nothing to apply")
    # In time order, on the runtime's clock.
    assert [entry.time for entry in found] == sorted(entry.time for entry in found)
