"""A standby of a redundant pair takes over the active's alarm states: acknowledged, shelved, out of service, delays.

Two runtimes of one plant in one process on a simulated clock (tests/engine/test_replication.py's
`Pair`), each with its alarms adapter: the active's alarm states travel with every cycle's state,
and the successor carries on with them — no alarm comes back as new and unacknowledged, no
transition is journaled twice, a shelving expires when it was due on the old active.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from softplc.app.adapters import build_adapters
from softplc.config import PlantConfig
from softplc.core.events import Event
from softplc.core.plant import StateRefused
from softplc.core.plant_role import PlantRole, RoleTerm
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from tests.engine.test_replication import Pair

OPERATOR = Origin("hmi", "olga", "127.0.0.1", role=Role.OPERATOR)
ENGINEER = Origin("cli", "erin", "127.0.0.1", role=Role.ENGINEER)
DRIVER = Origin("test-driver", role=None)

PLANT = """
version: 1
plant: {name: alarm-pair}
servers:
  opcua: {enabled: false}
  modbus: {enabled: false}
  hmi: {enabled: false}
tags:
  level: {type: float64}
  fault: {type: bool}
  door: {type: bool}
  jam: {type: bool}
  slow: {type: bool}
tasks:
  fast: {interval: 10ms}
alarms:
  definitions:
    - {name: level_hi, limit: {tag: level, hi: 90, hihi: {limit: 100, priority: critical}}, priority: high, message: "level {value:.0f}"}
    - {name: fault_on, discrete: {tag: fault, value: true}}
    - {name: door_open, discrete: {tag: door, value: true}}
    - {name: jam_on, discrete: {tag: jam, value: true}, latch: true}
    - {name: slow_on, discrete: {tag: slow, value: true}, on_delay: 1s}
"""


class AlarmPair(Pair):
    """A Pair whose runtimes run their alarms adapters; records every alarm event of each."""

    def __init__(self, config: PlantConfig, tmp_path: Path) -> None:
        super().__init__(config, tmp_path)
        self.events: dict[str, list[Event]] = {"a": [], "b": []}
        for name, runtime in (("a", self.active), ("b", self.standby)):
            for adapter in build_adapters(config, None):
                if adapter.name == "alarms":
                    runtime.add_adapter(adapter)
            runtime.events.subscribe(self.events[name].append, kinds=("alarm",))

    async def fail_over(self) -> int:
        """The active dies at this instant (fenced: no cycle, no evaluation; stopped at the end) and the standby takes over.

        (Stopping it first would let the simulated clock run on while its journal's thread stops.)
        """
        self.linked = False
        self.active.role.set(RoleTerm(PlantRole.FENCED, 1))
        resumed = self.standby.plant.replication.take_over()
        self.standby.role.set(RoleTerm(PlantRole.ACTIVE, 2, active="b"))
        return resumed

    def transitions(self, member: str) -> list[tuple[str, str]]:
        return [(event.data["transition"], event.source) for event in self.events[member]]


@pytest.fixture
async def pair(make_config: Callable[[str], PlantConfig], tmp_path: Path) -> Any:
    pair = AlarmPair(make_config(PLANT), tmp_path)
    await pair.start()
    yield pair
    await pair.stop()


async def listed(runtime: Any) -> dict[str, dict[str, Any]]:
    """The alarms as the HMI and the OPC UA server see them (the `alarms.list` query), by name."""
    return {item["name"]: item for item in await runtime.commands.call("alarms.list", {}, OPERATOR)}


async def test_the_successor_shows_acknowledged_shelved_and_out_of_service_alarms_as_they_were(pair: AlarmPair) -> None:
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.05)
    active.db.submit([("level", 95.0), ("fault", True), ("door", True), ("jam", True), ("slow", True)], DRIVER)
    await pair.clock.sleep_until(0.1)
    await active.commands.call("alarms.acknowledge", {"alarm": "level_hi", "comment": "pump checked"}, OPERATOR)
    await active.commands.call("alarms.shelve", {"alarm": "fault_on", "reason": "sensor in repair", "duration": "2s"}, OPERATOR)
    await active.commands.call("alarms.out_of_service", {"alarm": "door_open", "reason": "door removed"}, ENGINEER)
    active.db.submit([("jam", False)], DRIVER)  # a latching alarm returns: latched until acknowledged
    await pair.clock.sleep_until(0.5)  # slow_on's on-delay (1 s) runs, from 0.05
    before = await listed(active)
    assert before["level_hi"]["state"] == "acknowledged" and before["jam_on"]["state"] == "latched"
    # the standby's own view (its queries) is the active's already
    mirrored = await listed(standby)
    for name in ("level_hi", "fault_on", "door_open", "jam_on"):
        assert mirrored[name]["state"] == before[name]["state"], name
    assert mirrored["level_hi"]["comment"] == "pump checked" and mirrored["level_hi"]["comment_user"] == "olga"
    assert pair.transitions("b") == []  # a standby annunciates nothing of its own

    await pair.fail_over()
    await pair.clock.sleep_until(0.8)
    after = await listed(standby)
    assert after["level_hi"]["state"] == "acknowledged" and after["level_hi"]["acknowledged"]
    assert after["level_hi"]["priority"] == "high" and after["level_hi"]["message"] == "level 95"
    assert after["level_hi"]["sequence"] == before["level_hi"]["sequence"]
    assert after["fault_on"]["state"] == "shelved" and after["fault_on"]["shelving"]["reason"] == "sensor in repair"
    assert after["fault_on"]["shelving"]["until"] == before["fault_on"]["shelving"]["until"]
    assert after["door_open"]["state"] == "out_of_service"
    assert after["jam_on"]["state"] == "latched"
    summary = await standby.commands.call("alarms.summary", {}, OPERATOR)
    assert (summary["active"], summary["unacknowledged"], summary["shelved"]) == (1, 1, 1)  # level_hi; jam_on latched; fault_on
    assert standby.db.value("_sys.alarms.unacknowledged") == 1
    assert pair.transitions("b") == []  # nothing activated again, nothing journaled twice

    # timers carry on: slow_on's on-delay ends 1 s after 0.05 (not 1 s after the takeover), the
    # shelving 2 s after it was shelved on the old active
    await pair.clock.sleep_until(1.2)
    assert pair.transitions("b") == [("activated", "slow_on")]
    await pair.clock.sleep_until(2.2)
    assert pair.transitions("b") == [("activated", "slow_on"), ("shelving_expired", "fault_on")]
    assert (await listed(standby))["fault_on"]["state"] == "unacknowledged"
    assert await standby.commands.call("alarms.acknowledge", {"alarm": "jam_on"}, OPERATOR) == "acknowledged jam_on (now normal)"


async def test_an_alarm_transition_of_the_last_cycle_is_not_annunciated_again_by_the_successor(pair: AlarmPair) -> None:
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.055)
    active.db.submit([("fault", True)], DRIVER)
    await pair.clock.sleep_until(0.065)  # the cycle at 0.06 applied the write and evaluated the alarm: it is the last
    assert pair.transitions("a") == [("activated", "fault_on")]
    await pair.fail_over()
    await pair.clock.sleep_until(0.2)
    assert pair.transitions("b") == []
    assert (await listed(standby))["fault_on"]["state"] == "unacknowledged"


async def test_a_malformed_alarm_state_is_refused_and_nothing_of_its_state_is_applied(pair: AlarmPair) -> None:
    active, standby = pair.active, pair.standby
    await pair.clock.sleep_until(0.05)
    pair.linked = False
    active.db.submit([("fault", True), ("level", 50.0)], DRIVER)
    await pair.clock.sleep_until(0.1)
    door = standby.plant.replication
    state = active.plant.replication.capture_full()
    assert "alarms" in state[9]
    good = state[9]["alarms"]
    for broken, reason in (
        ("nonsense", "alarms"),
        ([["no_such_alarm", *good[0][1:]]], "no_such_alarm"),
        ([[good[0][0], "yes", *good[0][2:]]], "active"),
        ([[good[0][0], good[0][1], "sideways", *good[0][3:]]], "level"),
        ([[good[0][0], *good[0][1:4], "panicking", *good[0][5:]]], "state"),
        ([good[0][:3]], "expected a list"),
    ):
        with pytest.raises(StateRefused, match=reason):
            door.apply([*state[:9], {"alarms": broken}])
    assert standby.db.value("level") == 0.0  # nothing of the refused states, not even their tags
    door.apply(state)
    assert standby.db.value("level") == 50.0
    assert (await listed(standby))["fault_on"]["state"] == "unacknowledged"
