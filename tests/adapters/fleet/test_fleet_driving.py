"""Simulated robots driven by the fleet adapter on the simulated clock: stations, limits, traffic."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO
from fleet_support import Plant, min_separation, robot_yaml, write_plant

from softplc.adapters.fleet.adapter import FleetAdapter
from softplc.app.runtime import AdapterError, Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from softplc.robotics.gridmap import OccupancyGrid, load_map
from softplc.robotics.loop import Sample

FACTORY = REPO / "robots" / "maps" / "factory.yaml"
STATIONS = [(3.5, 7.5), (1.8, 2.5), (18.5, 7.5), (20.1, 2.4)]  # SPEC §2: both tasks' source and destination
EPSILON = 1e-6


def check_limits(trace: list[Sample], linear: float, angular: float) -> None:
    """Speeds measured on the recorded trajectory (not the commands) never exceed the limits."""
    for a, b in zip(trace, trace[1:]):
        dt = b.t - a.t
        assert math.hypot(b.x - a.x, b.y - a.y) <= linear * dt * (1 + EPSILON) + EPSILON, (a, b)
        turned = abs(math.remainder(b.heading - a.heading, math.tau))
        assert turned <= angular * dt * (1 + EPSILON) + EPSILON, (a, b)


def check_on_free_floor(plant: Plant, robot_id: str) -> None:
    floor, radius = plant.fleet.floor, plant.fleet.robots[robot_id].radius
    for sample in plant.fleet.trajectory(robot_id):
        assert floor.grid.is_free(sample.x, sample.y), sample
        assert floor.clearance(sample.x, sample.y) >= radius, sample  # the footprint touches no wall


async def test_one_robot_visits_every_station_of_the_factory_map(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925)])
    async with Plant(tagdb, load_map(FACTORY)) as plant:
        db = plant.db
        for x, y in [*STATIONS, (7.925, 5.925)]:
            took = await plant.trip("r01", x, y, limit=200)
            assert db.value("r01_navstate") == "arrived", db.value("r01_navreason")
            assert math.hypot(db.value("r01_xpos") - x, db.value("r01_ypos") - y) <= 0.5
            assert took < 200
            # It keeps creeping to the goal after clearing its status (the sequencer wants < 0.3 m).
            await plant.run_until(lambda: plant.fleet.drivers["r01"].path is None, limit=10)
            pose = plant.fleet.pose("r01")
            assert math.hypot(pose.x - x, pose.y - y) <= 0.12
        trace = plant.fleet.trajectory("r01")
        check_limits(trace, 0.2, 0.4)
        check_on_free_floor(plant, "r01")
        assert max(abs(s.speed) for s in trace) == pytest.approx(0.2)  # it does use its full speed
        assert plant.fleet.drivers["r01"].plans == 5  # one plan per goal, never per cycle
        states = [s.navstate for s in trace]
        assert states[0] == "planning" and "moving" in states and states[-1] == "arrived"
        assert plant.fleet.stats()["r01"].overruns == 0


async def test_status_is_cleared_within_half_a_metre_and_tags_follow_the_robot(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 2.0, 1.6)])
    grid = OccupancyGrid(np.pad(np.zeros((60, 160), dtype=bool), 2, constant_values=True), 0.05)  # 8.2 x 3.2 m
    async with Plant(tagdb, grid) as plant:
        db = plant.db
        await plant.clock.sleep(0.2)
        assert db.value("r01_radius") == pytest.approx(plant.fleet.robots["r01"].radius)
        plant.send("r01", 6.0, 1.6)
        await plant.run_until(lambda: db.value("r01_status"), limit=1)
        await plant.run_until(lambda: not db.value("r01_status"), limit=60, step=0.01)
        assert 0.4 <= 6.0 - db.value("r01_xpos") <= 0.5  # cleared as soon as it is within 0.5 m
        assert db.value("r01_navstate") == "arrived" and db.value("r01_heading") == pytest.approx(0.0, abs=0.05)
        route = db.value("r01_route")
        assert route.startswith("2.00,1.60") and route.endswith("6.00,1.60")


async def test_unreachable_goal_fails_clearly_without_moving(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925)])
    async with Plant(tagdb, load_map(FACTORY)) as plant:
        plant.send("r01", 12.5, 4.3)  # inside the rack island
        await plant.run_until(lambda: plant.db.value("r01_navstate") == "failed", limit=5)
        assert not plant.db.value("r01_status")
        assert "inside an obstacle" in plant.db.value("r01_navreason")
        await plant.clock.sleep(5)
        trace = plant.fleet.trajectory("r01")
        assert {(s.x, s.y, s.heading) for s in trace} == {(7.925, 5.925, 0.0)}  # no spinning, no creeping
        # Asked again with status set (a sequencer's retry), it tries again and fails again.
        plans = plant.fleet.drivers["r01"].plans
        plant.db.submit([("r01_status", True)], "test")
        await plant.run_until(lambda: plant.fleet.drivers["r01"].plans == plans + 1, limit=2)
        await plant.run_until(lambda: plant.db.value("r01_navstate") == "failed" and not plant.db.value("r01_status"), limit=2)


async def test_runs_are_deterministic_and_the_cycle_is_configurable(tmp_path: Path) -> None:
    traces = []
    for run in range(2):
        directory = tmp_path / str(run)
        directory.mkdir()
        tagdb = write_plant(directory, [robot_yaml("r01", 7.925, 5.925), robot_yaml("r02", 7.925, 2.925)])
        async with Plant(tagdb, load_map(FACTORY), cycle=0.05) as plant:
            plant.send("r01", 3.5, 7.5)
            plant.send("r02", 1.8, 2.5)
            await plant.clock.sleep(30)
            traces.append([plant.fleet.trajectory(r) for r in ("r01", "r02")])
    assert traces[0] == traces[1]
    times = [s.t for s in traces[0][0]]
    assert np.allclose(np.diff(times), 0.05)


async def test_a_new_goal_mid_trip_replans_from_where_the_robot_is(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925)])
    async with Plant(tagdb, load_map(FACTORY)) as plant:
        plant.send("r01", 18.5, 7.5)
        await plant.clock.sleep(10)
        await plant.trip("r01", 1.8, 2.5, limit=150)
        assert plant.db.value("r01_navstate") == "arrived"
        assert plant.fleet.drivers["r01"].plans == 2


def aisle_map(width: float) -> OccupancyGrid:
    """A 16 x 6 m hall with an 8 m aisle of the given width in the middle."""
    resolution = 0.05
    occupied = np.zeros((int(6 / resolution), int(16 / resolution)), dtype=bool)
    occupied[:2, :] = occupied[-2:, :] = occupied[:, :2] = occupied[:, -2:] = True
    low, high = round((3 - width / 2) / resolution), round((3 + width / 2) / resolution)
    occupied[:low, 80:240] = occupied[high:, 80:240] = True
    return OccupancyGrid(occupied, resolution)


CROSSINGS = {
    # id, start x, y, heading, goal x, y: head-on through the aisle (and a third one cutting across)
    2: [("r01", 2.0, 3.0, 0.0, 14.0, 3.0), ("r02", 14.0, 3.0, math.pi, 2.0, 3.0)],
    3: [("r01", 2.0, 3.0, 0.0, 14.0, 3.0), ("r02", 14.0, 3.0, math.pi, 2.0, 3.0), ("r03", 14.0, 4.5, math.pi, 2.0, 1.5)],
}


@pytest.mark.parametrize("count", [2, 3])
@pytest.mark.parametrize("width", [1.6, 2.4])
async def test_robots_crossing_in_an_aisle_never_collide_or_deadlock(tmp_path: Path, count: int, width: float) -> None:
    robots = CROSSINGS[count]
    tagdb = write_plant(tmp_path, [robot_yaml(r, x, y, h) for r, x, y, h, *_ in robots])
    async with Plant(tagdb, aisle_map(width)) as plant:
        for robot_id, *_, gx, gy in robots:
            plant.send(robot_id, gx, gy)
        ids = [r[0] for r in robots]
        await plant.run_until(lambda: plant.idle(*ids), limit=400)
        for robot_id, *_, gx, gy in robots:
            assert plant.db.value(f"{robot_id}_navstate") == "arrived", plant.db.value(f"{robot_id}_navreason")
            check_limits(plant.fleet.trajectory(robot_id), 0.2, 0.4)
            check_on_free_floor(plant, robot_id)
        # Every cycle, every pair: the footprints never touch (the rule keeps 0.12 m between them).
        gap, when = min_separation(plant, ids)
        assert gap > 0.05, f"footprints {gap:.3f} m apart at t={when:.1f}"
        states = {s.navstate for r in ids for s in plant.fleet.trajectory(r)}
        assert "blocked" in states  # they did meet: someone yielded


async def test_fleet_adapter_from_the_default_plant(tmp_path: Path) -> None:
    config = load_config(REPO / "tagdb.yaml")
    fleet = FleetAdapter.from_config(config, record=True)
    runtime = Runtime(config, SimClock(), state_dir=tmp_path)
    runtime.add_adapter(fleet)
    assert "3 robots (3 simulated, 0 remote)" in fleet.describe() and "21.95 x 8.60 m" in fleet.describe()
    await runtime.start()
    try:
        for robot in fleet.robots:
            assert (fleet.pose(robot.id).x, fleet.pose(robot.id).y) == (robot.start.x, robot.start.y)
        # The default plant's sequencers and dispatcher send the robots to the stations.
        await runtime.clock.sleep(60.0)
        for robot in fleet.robots:
            assert runtime.db.value(f"{robot.id}_radius") == pytest.approx(robot.radius)
            trace = fleet.trajectory(robot.id)
            assert len(trace) == pytest.approx(600, abs=2)
            check_limits(trace, 0.2, 0.4)
        assert any(s.navstate == "moving" for robot in fleet.robots for s in fleet.trajectory(robot.id))
        assert all(stats.overruns == 0 for stats in fleet.stats().values())
    finally:
        await runtime.stop()


async def test_missing_robot_tags_are_a_clear_start_error(tmp_path: Path) -> None:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925)])
    tagdb.write_text(tagdb.read_text().replace("      navstate:  {type: string, initial: idle, access: ro}\n", ""))
    plant = Plant(tagdb, load_map(FACTORY))
    with pytest.raises(AdapterError, match="need tags that tagdb.yaml does not declare: r01_navstate"):
        await plant.runtime.start()
    await plant.runtime.stop()
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 12.5, 4.3)])
    plant = Plant(tagdb, load_map(FACTORY))
    with pytest.raises(AdapterError, match=r"robots.yaml:\d+:\d+: robot r01 starts at \(12.5, 4.3\), which is not free floor"):
        await plant.runtime.start()
    await plant.runtime.stop()


async def test_robots_of_one_phase_share_a_task_and_each_keeps_its_own_cycle(tmp_path: Path) -> None:
    # 12 robots in ten phase slots: r01 and r11, r02 and r12 step in one task each, one after the other.
    resolution = 0.05
    occupied = np.zeros((int(14 / resolution), int(30 / resolution)), dtype=bool)
    occupied[:2, :] = occupied[-2:, :] = occupied[:, :2] = occupied[:, -2:] = True
    hall = OccupancyGrid(occupied, resolution)
    robots = [(f"r{n:02d}", 2.0 + 2.2 * ((n - 1) % 12), 2.0) for n in range(1, 13)]
    traces = []
    for run in range(2):
        directory = tmp_path / str(run)
        directory.mkdir()
        tagdb = write_plant(directory, [robot_yaml(r, x, y, math.pi / 2) for r, x, y in robots])
        async with Plant(tagdb, hall) as plant:
            assert len(plant.fleet._tasks) == 10 and len(plant.fleet.loops) == 12
            for robot_id, x, _ in robots:
                plant.send(robot_id, x, 10.0)
            await plant.run_until(lambda: plant.idle(*[r for r, *_ in robots]), limit=120)
            for robot_id, x, _ in robots:
                assert plant.db.value(f"{robot_id}_navstate") == "arrived", plant.db.value(f"{robot_id}_navreason")
                assert math.dist((plant.db.value(f"{robot_id}_xpos"), plant.db.value(f"{robot_id}_ypos")), (x, 10.0)) < 0.5
            traces.append({r: plant.fleet.trajectory(r) for r, *_ in robots})
            stats = plant.fleet.stats()
            assert stats["r01"].cycles == stats["r11"].cycles and stats["r01"].overruns == 0
    assert traces[0] == traces[1]
    first, eleventh, second = ([s.t for s in traces[0][r]] for r in ("r01", "r11", "r02"))
    assert first == eleventh and np.allclose(np.diff(first), 0.1)  # one slot: the same instants
    assert second[0] - first[0] == pytest.approx(0.01)  # the next slot, a tenth of a cycle later
