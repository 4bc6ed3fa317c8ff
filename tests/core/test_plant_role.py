"""The plant's role (softplc/core/plant_role.py): an active term that lapses fences the plant at once,
before anyone has told it — the engine scans nothing and the tag database refuses every write."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from softplc.app.runtime import Runtime
from softplc.config import PlantConfig
from softplc.core.clock import SimClock
from softplc.core.plant_role import PlantRole, RoleHolder, RoleTerm
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule

OPERATOR = Origin("opcua", "olga", role=Role.OPERATOR)
PLANT = """
version: 1
tags:
  n: {type: uint32}
  setpoint: {type: float64}
tasks:
  fast:
    interval: 10ms
    programs:
      - {name: count, program: "tests.core_programs:Counter", bind: {count: n}}
"""


def test_alone_a_plant_is_active_for_ever() -> None:
    holder = RoleHolder(lambda: 1e12)
    assert holder.is_active() and holder.role is PlantRole.ACTIVE and holder.refusal() == ""


def test_an_active_term_lapses_at_its_end_and_a_renewal_extends_it() -> None:
    now = [0.0]
    holder = RoleHolder(lambda: now[0])
    heard: list[RoleTerm] = []
    holder.on_change(heard.append)
    holder.set(RoleTerm(PlantRole.ACTIVE, 3, until=2.0, active="a"))
    now[0] = 1.9
    assert holder.is_active()
    holder.renew(3.0)
    now[0] = 2.5
    assert holder.is_active() and len(heard) == 1  # a renewal tells nobody
    now[0] = 3.0
    assert not holder.is_active() and holder.role is PlantRole.FENCED
    assert "epoch 3" in holder.refusal() and "lapsed" in holder.refusal()
    holder.set(RoleTerm(PlantRole.FENCED, 3))
    holder.renew(10.0, 3)  # a lease keeper's late renewal never revives a term set meanwhile
    assert holder.role is PlantRole.FENCED
    holder.set(RoleTerm(PlantRole.ACTIVE, 4, until=3.5))
    holder.renew(10.0, 3)  # nor extends another epoch's
    assert holder.term.until == 3.5
    holder.set(RoleTerm(PlantRole.STANDBY, 4, active="b", detail="write to the active, b"))
    assert holder.refusal() == "write to the active, b"
    assert [term.role for term in heard] == [PlantRole.ACTIVE, PlantRole.FENCED, PlantRole.ACTIVE, PlantRole.STANDBY]


async def test_a_lapsed_term_stops_the_scan_and_the_writes_at_once_and_a_new_term_resumes_them(
        make_config: Callable[[str], PlantConfig], tmp_path: Any) -> None:
    clock = SimClock()
    runtime = Runtime(make_config(PLANT), clock, state_dir=tmp_path, retain=False)
    runtime.role.set(RoleTerm(PlantRole.ACTIVE, 1, until=0.105, active="a"))
    await runtime.start()
    try:
        await clock.sleep_until(0.2)
        assert runtime.db.value("n") == 11  # cycles at 0.00 ... 0.10, none after the term's end
        (refused,) = runtime.db.submit([("setpoint", 1.0)], OPERATOR)
        assert refused is not None and refused.rule is Rule.NOT_ACTIVE
        runtime.role.set(RoleTerm(PlantRole.ACTIVE, 2, until=10.0, active="a"))  # at 0.2: cycles 0.20 ... 0.30 follow
        await clock.sleep_until(0.305)
        assert runtime.db.value("n") == 22 and runtime.db.submit([("setpoint", 1.0)], OPERATOR) == [None]
        task = runtime.tasks[0]
        assert task.stats.overruns == 0  # the releases that passed are no overruns
    finally:
        await runtime.stop()


async def test_a_standby_refuses_actions_naming_the_active_but_answers_queries() -> None:
    from softplc.core.commands import CommandRefused, Commands, Permission

    holder = RoleHolder(lambda: 0.0)
    commands = Commands(lambda: 0.0)
    commands.refusal = holder.refusal
    calls: list[Any] = []
    commands.on_call(calls.append)
    commands.register("plant.act", lambda arguments, origin: "done", permission=Permission.ACKNOWLEDGE)
    commands.register("plant.look", lambda arguments, origin: "seen", permission=Permission.VIEW)
    commands.register("pair.switch", lambda arguments, origin: "switched", permission=Permission.ENGINEER, on_standby=True)
    holder.set(RoleTerm(PlantRole.STANDBY, 2, active="a", detail="this runtime (b) is the standby: act on the active, a"))
    try:
        await commands.call("plant.act", {}, OPERATOR)
        raise AssertionError("a standby carried out an action")
    except CommandRefused as refused:
        assert "act on the active, a" in str(refused)
    assert calls[-1].accepted is False
    assert await commands.call("plant.look", {}, OPERATOR) == "seen"
    assert await commands.call("pair.switch", {}, Origin("cli", "erin", role=Role.ENGINEER)) == "switched"


def test_a_program_asks_whether_it_may_drive_at_the_moment_it_sends() -> None:
    """A process frozen in the middle of a scan wakes up in that scan, past its term: `driving` says so there."""
    from softplc.core.program import Program, ProgramContext

    now = [0.0]
    holder = RoleHolder(lambda: now[0])
    holder.set(RoleTerm(PlantRole.ACTIVE, 5, until=1.0, active="a"))
    program = Program(ProgramContext("out", SimClock(), {}, plant_role=holder))
    alone = Program(ProgramContext("alone", SimClock(), {}))
    assert program.driving and program.epoch == 5 and alone.driving and alone.epoch == 0
    now[0] = 1.0  # the scan began before the term's end; the freeze ended after it
    assert not program.driving and program.epoch == 5
    holder.set(RoleTerm(PlantRole.STANDBY, 6, active="b"))
    assert not program.driving


def test_a_standby_sets_its_own_diagnostic_tags_at_once_and_refuses_a_drivers_plant_tags() -> None:
    """A standby runs no cycle: an adapter's `_sys.` status (never mirrored) is set at once; plant tags are the active's."""
    from softplc.core.datatypes import DataType
    from softplc.core.tagdb import TagDatabase
    from softplc.core.tags import Access, TagDef

    db = TagDatabase([TagDef("setpoint", DataType.FLOAT64, 0.0),
                      TagDef("_sys.link.state", DataType.STRING, "", access=Access.RO, group="_sys", runtime_only=True)], lambda: 0.0)
    db.role = RoleHolder(lambda: 0.0)
    db.role.set(RoleTerm(PlantRole.STANDBY, 2, active="a", detail="write to the active, a"))
    driver = Origin("links", role=None)
    results = db.submit([("_sys.link.state", "up"), ("setpoint", 2.0), ("_sys.link.state", 7)], driver)
    assert results[0] is None and db.value("_sys.link.state") == "up"
    assert results[1] is not None and results[1].rule is Rule.NOT_ACTIVE and db.value("setpoint") == 0.0
    assert results[2] is not None and results[2].rule is Rule.TYPE_MISMATCH  # checked like any write
    (refused,) = db.submit([("_sys.link.state", "down")], OPERATOR)  # a client never writes a diagnostic tag
    assert refused is not None and db.value("_sys.link.state") == "up"
