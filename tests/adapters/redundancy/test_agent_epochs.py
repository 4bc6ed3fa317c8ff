"""A robot agent obeys only the newest active of a redundant pair: a standby's, a fenced or an older active's goals are ignored."""

from __future__ import annotations

from softplc.clients.robot_agent.agent import EPOCH, ROLE, Epochs, SubscriptionIO


class _Node:
    def __init__(self, name: str) -> None:
        self.nodeid = type("NodeId", (), {"Identifier": name})()


def _io(epochs: Epochs, paired: bool = True) -> SubscriptionIO:
    io = SubscriptionIO.__new__(SubscriptionIO)
    io.id, io.values, io.epochs, io.paired, io.session = "r01", {}, epochs, paired, ""
    io.values.update({"r01_xgoal": 3.5, "r01_ygoal": 7.5, "r01_status": True})
    return io


def test_goals_of_the_newest_active_only() -> None:
    epochs = Epochs()
    new = _io(epochs)
    new.values.update({ROLE: "ACTIVE", EPOCH: 7})
    assert new.command() is not None and epochs.highest == 7
    old = _io(epochs)
    old.values.update({ROLE: "ACTIVE", EPOCH: 5})  # a frozen active woke up and still says ACTIVE: its epoch is older
    assert old.command() is None
    standby = _io(epochs)
    standby.values.update({ROLE: "STANDBY", EPOCH: 7})
    assert standby.command() is None
    fenced = _io(epochs)
    fenced.values.update({ROLE: "FENCED", EPOCH: 7})
    assert fenced.command() is None


def test_a_runtime_alone_is_always_obeyed() -> None:
    assert _io(Epochs(), paired=False).command() is not None
