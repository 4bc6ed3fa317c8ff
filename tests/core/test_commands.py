"""Commands and events: the core's door for actions (with origin and role) and its announcements."""

from __future__ import annotations

import pytest

from softplc.core.commands import CommandCall, CommandRefused, Commands, Permission, UnknownCommand
from softplc.core.events import Event, EventBus
from softplc.core.roles import Role
from softplc.core.tagdb import Origin

VIEWER = Origin("hmi", user="vera", role=Role.VIEWER)
OPERATOR = Origin("opcua", user="otto", role=Role.OPERATOR)
ENGINEER = Origin("cli", user="erin", peer="10.0.0.9", role=Role.ENGINEER)


async def test_the_role_decides_on_every_path_and_every_call_is_reported() -> None:
    commands = Commands(lambda: 1234.0)
    acknowledged: list[str] = []
    calls: list[CommandCall] = []
    commands.on_call(calls.append)

    def acknowledge(arguments: dict, origin: Origin) -> str:
        if arguments["alarm"] == "nope":
            raise CommandRefused("no alarm 'nope'")
        acknowledged.append(arguments["alarm"])
        return f"acknowledged {arguments['alarm']}"

    async def restart(arguments: dict, origin: Origin) -> str:
        return "restarted"

    commands.register("alarms.acknowledge", acknowledge, permission=Permission.ACKNOWLEDGE,
                      description="acknowledge alarms", arguments={"alarm": "alarm name"})
    commands.register("programs.restart", restart, permission=Permission.ENGINEER, description="restart programs")
    commands.register("alarms.list", lambda arguments, origin: ["a"], permission=Permission.VIEW)

    with pytest.raises(CommandRefused, match="role viewer may not acknowledge alarms"):
        await commands.call("alarms.acknowledge", {"alarm": "t01_full"}, VIEWER)
    assert await commands.call("alarms.acknowledge", {"alarm": "t01_full"}, OPERATOR) == "acknowledged t01_full"
    with pytest.raises(CommandRefused, match="no alarm 'nope'"):
        await commands.call("alarms.acknowledge", {"alarm": "nope"}, OPERATOR)
    with pytest.raises(CommandRefused, match="unknown argument 'alrm'"):
        await commands.call("alarms.acknowledge", {"alrm": "x"}, OPERATOR)
    with pytest.raises(CommandRefused, match="role operator may not restart programs"):
        await commands.call("programs.restart", {}, OPERATOR)
    assert await commands.call("programs.restart", {}, ENGINEER) == "restarted"
    with pytest.raises(UnknownCommand):
        await commands.call("programs.explode", {}, ENGINEER)
    assert await commands.call("alarms.list", {}, VIEWER) == ["a"]  # reading: any role, not audited
    assert await commands.call("programs.restart", {}, Origin("runtime", role=None)) == "restarted"  # internal: not audited

    assert acknowledged == ["t01_full"]
    assert [(c.command, c.origin.user, c.accepted, c.detail) for c in calls] == [
        ("alarms.acknowledge", "vera", False, "role viewer may not acknowledge alarms"),
        ("alarms.acknowledge", "otto", True, "acknowledged t01_full"),
        ("alarms.acknowledge", "otto", False, "no alarm 'nope'"),
        ("alarms.acknowledge", "otto", False, "alarms.acknowledge: unknown argument 'alrm'; it takes: alarm"),
        ("programs.restart", "otto", False, "role operator may not restart programs"),
        ("programs.restart", "erin", True, "restarted"),
        ("programs.explode", "erin", False, "no such command 'programs.explode'"),
    ]
    assert all(c.time == 1234.0 for c in calls)
    with pytest.raises(ValueError):
        commands.register("programs.restart", restart, permission=Permission.ENGINEER)


def test_events_reach_the_subscribers_of_their_kind_and_a_broken_one_harms_nobody() -> None:
    bus = EventBus()
    alarms: list[Event] = []
    everything: list[Event] = []

    def broken(event: Event) -> None:
        raise RuntimeError("subscriber bug")

    bus.subscribe(broken)
    bus.subscribe(alarms.append, kinds=["alarm"])
    unsubscribe = bus.subscribe(everything.append)
    bus.publish(Event("alarm", 1.0, "t01_full", {"active": True}))
    bus.publish(Event("program", 2.0, "plant"))
    unsubscribe()
    bus.publish(Event("alarm", 3.0, "t01_full", {"active": False}))
    assert [e.time for e in alarms] == [1.0, 3.0]
    assert [e.time for e in everything] == [1.0, 2.0]
