"""The JSON summary of a scenario run: duration, goals and trips, throughput, utilisation, stuck time."""

from __future__ import annotations

from typing import Any

from softplc.core.tagdb import TagDatabase
from softplc.scenarios.recorder import Recorder
from softplc.scenarios.spec import Scenario


def summarise(scenario: Scenario, db: TagDatabase, recorder: Recorder, duration: float, stop_reason: str) -> dict[str, Any]:
    """Everything a reader compares between runs, as plain JSON-ready values."""
    tasks = [task.id for task in scenario.tasks]
    value = db.value
    delivered = {task: int(value(f"{task}_qSM")) for task in tasks}
    robots: dict[str, Any] = {}
    for robot, record in recorder.robot_records.items():
        robots[robot] = {
            "trips": {tasks[number - 1]: count for number, count in sorted(record.trips.items()) if 1 <= number <= len(tasks)},
            "delivered": {tasks[number - 1]: count for number, count in sorted(record.delivered.items()) if 1 <= number <= len(tasks)},
            "idle_s": round(record.idle, 3),
            "stuck_s": round(record.stuck, 3),
            "longest_stuck_s": round(record.longest_stuck, 3),
            # the share of the run spent on a task and getting on with it
            "utilisation": round(1.0 - (record.idle + record.stuck) / duration, 4) if duration > 0 else 0.0,
            "distance_m": round(record.distance, 2),
            "navigation_failures": record.failures,
        }
    total = sum(delivered.values())
    full_at = {task: round(recorder.full_at[task], 3) for task in tasks if task in recorder.full_at}
    return {
        "scenario": scenario.name,
        "title": scenario.title,
        "dispatcher": scenario.dispatcher,
        "thesis": scenario.thesis,
        "stop": scenario.stop,
        "stop_reason": stop_reason,
        "sim_duration_s": round(duration, 3),
        "goals_per_task": {task: int(value(f"{task}_goals")) for task in tasks},
        "delivered_per_task": delivered,
        "levels_at_end": {task: {"in": round(float(value(f"{task}_iBL")), 2), "out": round(float(value(f"{task}_qSL")), 2)} for task in tasks},
        "throughput_items_per_min": round(60.0 * total / duration, 3) if duration > 0 else 0.0,
        "full_at_s": full_at,
        "makespan_s": max(full_at.values()) if len(full_at) == len(tasks) else None,
        "idle_s_total": round(sum(robot["idle_s"] for robot in robots.values()), 3),
        "stuck_s_total": round(sum(robot["stuck_s"] for robot in robots.values()), 3),
        "robots": robots,
        "trip_log": [[round(time, 1), robot, tasks[number - 1]] for time, robot, number in recorder.trip_log
                     if 1 <= number <= len(tasks)],
    }
