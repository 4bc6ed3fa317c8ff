"""Plants nobody tuned the fleet for: crowded stations and team limits, on the simulated clock.

The thesis scenarios seldom bring two robots to one station; these plants send four
robots to three stations 0.9 m apart, so robots meet at the same station all the time.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO

from softplc.app.runtime import Adapter
from softplc.config import PlantConfig
from softplc.core.plant import Plant
from softplc.scenarios.runner import RunResult, fleet_adapter, run_scenario
from softplc.scenarios.spec import Scenario, load_scenario

# Four robots, three tasks whose sources (and destinations) stand 0.9 m apart in one bay;
# 5 items per trip, so every robot keeps shuttling. Storages never fill (qSC 1000).
CROWDED = """\
scenario: {name: crowded, stop: time_limit, time_limit: 900}
plant: {handling_time: 5, park_after: 10}
dispatcher: {type: DISPATCHER}
tasks:
  - {id: t01, iFr: 30, qSC: 1000, source: {x: 7.0, y: 7.3}, destination: {x: 7.0, y: 1.2}}
  - {id: t02, iFr: 20, qSC: 1000, source: {x: 7.9, y: 7.3}, destination: {x: 7.9, y: 1.2}}
  - {id: t03, iFr: 10, qSC: 1000, source: {x: 8.8, y: 7.3}, destination: {x: 8.8, y: 1.2}}
robots:
  - {id: r01, loadcap: 5, start: {x: 6.5, y: 5.9}}
  - {id: r02, loadcap: 5, start: {x: 7.9, y: 2.9}}
  - {id: r03, loadcap: 5, start: {x: 7.9, y: 4.5}}
  - {id: r04, loadcap: 5, start: {x: 9.0, y: 5.9}}
"""

LONGEST_STILL = 90.0  # s a robot with work may stand in one place (queueing at a station included)
LONGEST_GAP = 250.0  # s between the starts of two trips of one robot (a round trip takes ~80 s)


def scenario(tmp_path: Path, text: str, name: str = "plant.yaml") -> Scenario:
    path = tmp_path / name
    path.write_text(text)
    return load_scenario(path)


def longest_still(result: RunResult, robot: str) -> float:
    """The longest time the robot stayed within 5 cm of one spot (from the XY record)."""
    header = result.recorder.xy_header
    x, y = header.index(f"{robot}_x"), header.index(f"{robot}_y")
    longest, since, anchor = 0.0, 0.0, None
    for row in result.recorder.xy:
        t, here = float(row[0]), (float(row[x]), float(row[y]))
        if anchor is None or math.dist(here, anchor) > 0.05:
            anchor, since = here, t
        longest = max(longest, t - since)
    return longest


@pytest.mark.parametrize("dispatcher", ["optimal", "weighting"])
def test_four_robots_at_three_close_stations_keep_completing_trips(tmp_path: Path, dispatcher: str) -> None:
    result = run_scenario(scenario(tmp_path, CROWDED.replace("DISPATCHER", dispatcher)))
    summary = result.summary
    assert summary["stop_reason"] == "time limit reached" and "faulted_programs" not in summary
    end = summary["sim_duration_s"]
    for robot, record in summary["robots"].items():
        starts = [0.0] + [t for t, who, _ in summary["trip_log"] if who == robot] + [end]
        gap = max(b - a for a, b in zip(starts, starts[1:]))
        assert gap <= LONGEST_GAP, f"{robot} went {gap:.0f} s without starting a trip: {record}"
        still = longest_still(result, robot)
        assert still <= LONGEST_STILL, f"{robot} stood still for {still:.0f} s: {record}"
        # the summary says how long it was held up, and utilisation leaves that time out
        assert record["longest_stuck_s"] <= LONGEST_STILL and record["stuck_s"] >= record["longest_stuck_s"]
        assert record["utilisation"] == pytest.approx(1 - (record["idle_s"] + record["stuck_s"]) / end, abs=1e-3)
    assert sum(summary["delivered_per_task"].values()) >= 100


def test_a_robot_kept_from_its_station_is_reported_stuck_and_gives_up(tmp_path: Path) -> None:
    # r02 can serve nothing and stands for good 0.45 m from task 1's source; r01 is sent there
    # and stops short of it, farther than the arrival tolerance (0.5 m).
    text = """\
scenario: {name: blocked, stop: time_limit, time_limit: 420}
dispatcher: {type: cooperative}
tasks:
  - {id: t01, requires: [gripper], source: {x: 7.0, y: 7.3}, destination: {x: 7.0, y: 1.2}}
robots:
  - {id: r01, start: {x: 7.0, y: 4.5}}
  - {id: r02, start: {x: 7.0, y: 6.85}, hardware: []}
"""
    result = run_scenario(scenario(tmp_path, text))
    record = result.summary["robots"]["r01"]
    assert record["navigation_failures"] >= 2  # gave up after 180 s, was asked again, gave up again
    assert record["stuck_s"] > 300 and record["longest_stuck_s"] > 180
    assert record["utilisation"] < 0.3
    assert result.summary["goals_per_task"] == {"t01": 1}


class TeamWatch:
    """The scenario's fleet, plus a check after every scan cycle of how many robots serve each task."""

    name = "fleet"

    def __init__(self, inner: Adapter, robots: list[str], tasks: int) -> None:
        self.inner, self.robots, self.tasks = inner, robots, tasks
        self.largest = [0] * tasks
        self.plant: Plant | None = None

    async def start(self, plant: Plant) -> None:
        self.plant = plant
        await self.inner.start(plant)
        plant.after_cycle(self.count)

    async def stop(self) -> None:
        await self.inner.stop()

    def describe(self) -> str:
        return self.inner.describe()

    def count(self, task: Any) -> None:
        assert self.plant is not None
        value = self.plant.tags.value
        team = [0] * self.tasks
        for robot in self.robots:
            number = value(f"{robot}_tcurr")
            if value(f"{robot}_currloc") in (1, 2, 3, 4) and 1 <= number <= self.tasks:
                team[number - 1] += 1
        self.largest = [max(a, b) for a, b in zip(self.largest, team)]


TEAMS = """\
scenario: {name: teams, stop: time_limit, time_limit: 400}
plant: {handling_time: 5, park_after: 10}
dispatcher: {type: DISPATCHER, model: MODEL}
tasks:
  - {id: t01, iFr: 30, qSC: 1000, max_team_size: 1, source: {x: 3.5, y: 7.5}, destination: {x: 1.8, y: 2.5}}
  - {id: t02, iFr: 30, qSC: 1000, max_team_size: 1, source: {x: 18.5, y: 7.5}, destination: {x: 20.1, y: 2.4}}
robots:
  - {id: r01, start: {x: 7.925, y: 5.925}}
  - {id: r02, start: {x: 7.925, y: 2.925}}
  - {id: r03, start: {x: 7.925, y: 4.525}}
"""


@pytest.mark.parametrize("dispatcher", ["weighting", "cooperative", "svm", "optimal"])
def test_every_dispatcher_keeps_each_team_within_its_max_team_size(tmp_path: Path, dispatcher: str) -> None:
    model = REPO / "scenarios" / "svm" / "case3-sim1-model.json"
    plant = scenario(tmp_path, TEAMS.replace("DISPATCHER", dispatcher).replace("MODEL", str(model)))
    watches: list[TeamWatch] = []

    def watched(spec: Scenario, config: PlantConfig) -> Adapter:
        watches.append(TeamWatch(fleet_adapter(spec, config), [robot.id for robot in spec.robots], len(spec.tasks)))
        return watches[0]

    result = run_scenario(plant, adapter_factory=watched)
    assert "faulted_programs" not in result.summary
    assert watches[0].largest == [1, 1]  # three robots, two teams of one: neither exceeded
    trips = [sum(record["trips"].values()) for record in result.summary["robots"].values()]
    assert sum(trips) >= 8  # two teams of one kept busy: about 80 s per round trip, 400 s
    if dispatcher != "optimal":  # the optimal one gives the places to the cheapest robots, whoever waited
        assert min(trips) >= 2  # the robot left without a place gets the next one that frees
