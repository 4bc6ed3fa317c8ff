"""Links between two softplc runtimes: the remote is a second `softplc run` in its own process (OPC UA and Modbus).

A value goes out to the remote, its program doubles it, and the result comes back in — over
OPC UA (by subscription, with an operator login from a password file) and Modbus (by polling).
Then the remote is frozen (SIGSTOP: connected but silent → UNCERTAIN at 2x the period, BAD at
5x, GOOD again on SIGCONT), killed (BAD at once, the alarm raised), and started again (GOOD
after a reconnect with backoff, the alarm cleared).
"""

from __future__ import annotations

import signal
import textwrap
from pathlib import Path

import pytest

from softplc.core.tags import Quality
from tests.links_support import SoftplcRemote, links_of, start_plant, wait_until

DOUBLER = '''
from softplc import Input, Output, Program


class Doubler(Program):
    given = Input("a value from the other runtime")
    twice = Output("twice that value")

    def scan(self) -> None:
        self.twice = 2 * self.given
'''

REMOTE = """
plant: {name: remote}
tags:
  Given: {type: int32, modbus: {table: holding, address: 0}}
  Twice: {type: int32, access: ro, modbus: {table: holding, address: 2}}
tasks:
  main:
    interval: 10ms
    programs:
      - {name: doubler, program: doubler.py:Doubler, bind: {given: Given, twice: Twice}}
"""


@pytest.fixture
async def remote(tmp_path: Path):
    (tmp_path / "doubler.py").write_text(textwrap.dedent(DOUBLER))
    server = SoftplcRemote(tmp_path, REMOTE)
    await server.start()
    yield server
    await server.kill()


def local_plant(remote: SoftplcRemote) -> str:
    return f"""
        plant: {{name: local}}
        links:
          line2:
            protocol: opcua
            endpoint: "{remote.endpoint}"
            user: link
            password_file: link.password
            period: 100ms
            timeout: 1s
            backoff_max: 2s
          press: {{protocol: modbus, host: 127.0.0.1, port: {remote.modbus_port}, period: 100ms, timeout: 1s, backoff_max: 2s}}
        tags:
          given: {{type: int32, link: {{name: line2, source: "ns={{ns}};s=Given", direction: out}}}}
          twice: {{type: int32, link: {{name: line2, source: "ns={{ns}};s=Twice"}}}}
          twice_modbus: {{type: int32, link: {{name: press, source: "holding:2"}}}}
        alarms: {{definitions: []}}
        """


async def test_values_make_a_round_trip_a_frozen_remote_goes_uncertain_then_bad_and_a_killed_one_reconnects(
        tmp_path: Path, remote: SoftplcRemote) -> None:
    # One test, one remote: starting a softplc takes seconds (its OPC UA server's address space).
    runtime = await start_plant(tmp_path, local_plant(remote))
    db = runtime.db
    opcua, modbus = links_of(runtime).links["line2"], links_of(runtime).links["press"]
    try:
        db.submit([("given", 21)], "test")
        await wait_until(lambda: db.value("twice") == 42 and db.value("twice_modbus") == 42, timeout=10, what="the round trip")
        assert db["twice"].quality is Quality.GOOD and db["twice_modbus"].quality is Quality.GOOD
        db.submit([("given", 4)], "test")
        await wait_until(lambda: db.value("twice") == 8 and db.value("twice_modbus") == 8, timeout=5)
        remote.signal(signal.SIGSTOP)
        last = {name: link.last_data for name, link in (("twice", opcua), ("twice_modbus", modbus))}
        await wait_until(lambda: db["twice"].quality is Quality.UNCERTAIN and db["twice_modbus"].quality is Quality.UNCERTAIN,
                         timeout=3, what="UNCERTAIN")
        uncertain = {name: runtime.clock.now() - since for name, since in last.items()}
        await wait_until(lambda: db["twice"].quality is Quality.BAD and db["twice_modbus"].quality is Quality.BAD, timeout=3, what="BAD")
        bad = {name: runtime.clock.now() - since for name, since in last.items()}
        for name in last:  # 2x and 5x the 100 ms period, seen within a half-period tick and a scan
            assert 0.2 <= uncertain[name] < 0.5 and 0.5 <= bad[name] < 0.9, (name, uncertain, bad)
        assert db.value("twice") == 8  # the last good value, now BAD
        remote.signal(signal.SIGCONT)
        await wait_until(lambda: db["twice"].quality is Quality.GOOD and db["twice_modbus"].quality is Quality.GOOD, timeout=10,
                         what="GOOD after SIGCONT")
        await remote.kill()
        await wait_until(lambda: db["twice"].quality is Quality.BAD and db["twice_modbus"].quality is Quality.BAD, timeout=3,
                         what="BAD when killed")
        await wait_until(lambda: not db.value("_sys.links.line2.connected") and not db.value("_sys.links.press.connected"), timeout=5)
        alarms = {alarm["name"]: alarm for alarm in await runtime.commands.call("alarms.list", {}, "test")}
        assert alarms["link_line2_down"]["active"] and alarms["link_press_down"]["active"], alarms
        await remote.start()
        await wait_until(lambda: db["twice"].quality is Quality.GOOD and db["twice_modbus"].quality is Quality.GOOD, timeout=15,
                         what="GOOD after the reconnect")
        assert db.value("_sys.links.line2.reconnects") >= 1 and db.value("_sys.links.press.reconnects") >= 1
        # The out tag was sent again at the reconnect: the new remote doubles it at once.
        await wait_until(lambda: db.value("twice") == 8, timeout=5)
        alarms = {alarm["name"]: alarm for alarm in await runtime.commands.call("alarms.list", {}, "test")}
        assert not alarms.get("link_line2_down", {}).get("active", False)
    finally:
        await runtime.stop()
