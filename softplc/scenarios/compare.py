"""Dispatchers side by side: the same plants under weighting, cooperative, SVM and optimal dispatch.

A dispatcher is run on a plant only where it can honour the plant: plain weighting and the
SVM send robots without looking at compatibility, so they run only where every robot can
serve every task (the SVM model also decides for one robot at a time, so only single-robot
plants); cooperative dispatch on a plant where everyone is compatible is the weighting itself.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from softplc.scenarios.runner import compatibility, run_scenario
from softplc.scenarios.spec import BUILTIN_DIR, DISPATCHERS, Scenario

THESIS_SCENARIOS = ("case1-sim1", "case1-sim2", "case2-sim1", "case2-sim2", "case3-sim1", "case3-sim2")
DEFAULT_MODEL = BUILTIN_DIR / "svm" / "case3-sim1-model.json"


def applicable(scenario: Scenario, dispatcher: str) -> str:
    """'' when `dispatcher` can run `scenario`'s plant, else why not."""
    everyone = all(len(allowed) == len(scenario.tasks) for allowed in compatibility(scenario))
    if dispatcher == "weighting" and not everyone:
        return "ignores compatibility"
    if dispatcher == "cooperative" and everyone:
        return "same as weighting"
    if dispatcher == "svm" and (not scenario.single_robot or len(scenario.tasks) != 2):
        return "one robot, two tasks only"
    return ""


def compare(
    scenarios: list[Scenario],
    *,
    stop: str = "all_full",
    time_limit: float = 3600.0,
    out_dir: Path | None = None,
    report: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """One row per plant and dispatcher (rows of dispatchers that cannot run say why)."""
    rows = []
    for scenario in scenarios:
        for dispatcher in DISPATCHERS:
            row: dict[str, Any] = {"plant": scenario.name, "dispatcher": dispatcher}
            why_not = applicable(scenario, dispatcher)
            if why_not:
                rows.append({**row, "skipped": why_not})
                continue
            model = scenario.model if scenario.dispatcher == "svm" else DEFAULT_MODEL
            # Runs that go on past the first full storage must not send robots to a full one
            # (the optimal dispatcher never does; the thesis's formulas need skip_full for it).
            variant = replace(scenario.with_dispatcher(dispatcher, model if dispatcher == "svm" else None), stop=stop,
                              skip_full=stop != "any_full")
            result = run_scenario(variant, out_dir / variant.name if out_dir else None, figures=False, time_limit=time_limit)
            summary = result.summary
            row.update({
                "sim_duration_s": summary["sim_duration_s"],
                "makespan_s": summary["makespan_s"],
                "first_full_s": min(summary["full_at_s"].values()) if summary["full_at_s"] else None,
                "delivered": sum(summary["delivered_per_task"].values()),
                "throughput_items_per_min": summary["throughput_items_per_min"],
                "idle_s": summary["idle_s_total"],
                "stuck_s": summary["stuck_s_total"],
                "goals": summary["goals_per_task"],
                "wall_time_s": summary["wall_time_s"],
            })
            if report:
                report(f"{variant.name}: {row['sim_duration_s']:.0f} s simulated in {row['wall_time_s']:.1f} s")
            rows.append(row)
    return rows


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table."""
    lines = ["| plant | dispatcher | first storage full (s) | makespan, all full (s) | items delivered | throughput (items/min) "
             "| robot idle (s) | robot stuck (s) | goals per task |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        if "skipped" in row:
            lines.append(f"| {row['plant']} | {row['dispatcher']} | — | — | — | — | — | — | ({row['skipped']}) |")
            continue
        makespan = f"{row['makespan_s']:.0f}" if row["makespan_s"] is not None else f"> {row['sim_duration_s']:.0f}"
        first = f"{row['first_full_s']:.0f}" if row["first_full_s"] is not None else "—"
        goals = " / ".join(str(count) for count in row["goals"].values())
        lines.append(f"| {row['plant']} | {row['dispatcher']} | {first} | {makespan} | {row['delivered']} | "
                     f"{row['throughput_items_per_min']:.2f} | {row['idle_s']:.0f} | {row['stuck_s']:.0f} | {goals} |")
    return "\n".join(lines)
