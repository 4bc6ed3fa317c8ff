"""Figures of a run in the thesis's style (matplotlib, Agg backend, PNG).

- levels_<name>.png: left, the input and output levels of every task against time (thesis
  Figures 5.4, 5.6, 5.8, 5.10); right, the task weights with the goals issued per task —
  or, for the SVM dispatcher, the SVM's output (1 or 2) and the demand levels (Figures 5.13, 5.14);
- xy_<name>.png: the robots' x/y paths over the map, with every task's source and
  destination (Figures 5.5, 5.7, 5.9, 5.11).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

# Figures made directly, not through pyplot: no backend to choose, no figure manager to close,
# and ~0.1 s less of imports per scenario run (matplotlib's own documented way for servers).
from matplotlib.figure import Figure

from softplc.scenarios.recorder import Recorder
from softplc.scenarios.spec import Scenario

TASK_COLOURS = ["tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown"]
ROBOT_COLOURS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"]
# A fixed date in PNG metadata would still differ between matplotlib versions; leave it out.
PNG_METADATA = {"Software": None}
FLOOR_M = (21.95, 8.6)  # the thesis's simulated floor, when no map is given


def _columns(header: list[str], rows: list[list[str]]) -> dict[str, list[float]]:
    return {name: [float(row[i]) for row in rows] for i, name in enumerate(header)}


def draw_figures(scenario: Scenario, recorder: Recorder, out_dir: Path, grid: Any = None) -> dict[str, Path]:
    """Draw both figures into `out_dir`; return their paths."""
    name = scenario.name
    levels = out_dir / f"levels_{name}.png"
    xy = out_dir / f"xy_{name}.png"
    draw_levels(scenario, recorder, levels)
    draw_paths(scenario, recorder, xy, grid)
    return {"levels_figure": levels, "xy_figure": xy}


def draw_levels(scenario: Scenario, recorder: Recorder, path: Path) -> None:
    lev = _columns(recorder.lev_header, recorder.lev)
    tsk = _columns(recorder.tsk_header, recorder.tsk)
    count = len(scenario.tasks)
    figure = Figure(figsize=(13, 4.6))
    left, right = figure.subplots(1, 2)
    time = lev["time"]
    for n in range(1, count + 1):
        colour = TASK_COLOURS[(n - 1) % len(TASK_COLOURS)]
        left.plot(time, lev[f"T{n}-in"], color=colour, linestyle="--", linewidth=1.2, label=f"T{n}-in")
        left.plot(time, lev[f"T{n}-out"], color=colour, linewidth=1.8, label=f"T{n}-out")
    left.set(title="Buffer levels", xlabel="time (s)", ylabel="level (%)", ylim=(-2, 105))
    left.grid(alpha=0.3)
    left.legend(loc="upper left", fontsize="small", ncols=2)
    if scenario.dispatcher == "svm":
        chosen = [task if task > 0 else float("nan") for task in lev["SVM-out"]]  # 0: before the first decision
        right.step(time, chosen, where="post", color="black", linewidth=1.2, label="SVM-out")
        right.set(ylabel="task chosen by the SVM", yticks=list(range(1, count + 1)), ylim=(0.5, count + 0.5))
        demand_axis = right.twinx()
        for n in range(1, count + 1):
            demand_axis.plot(time, lev[f"T{n}-D"], color=TASK_COLOURS[(n - 1) % len(TASK_COLOURS)], alpha=0.6,
                             linewidth=1, label=f"T{n}-D")
        demand_axis.set(ylabel="demand (%)", ylim=(-2, 105))
        right.set_title("SVM output and demand levels")
        _legend(right, demand_axis)
    else:
        what = "assignment cost (s/item)" if scenario.dispatcher == "optimal" else "task weight"
        for n in range(1, count + 1):
            right.plot(time, lev[f"T{n}-wt"], color=TASK_COLOURS[(n - 1) % len(TASK_COLOURS)], linewidth=1,
                       label=f"T{n}-wt")
        if scenario.dispatcher != "optimal":
            # Near-empty input buffers make x1 = 1 / (iFr * iBL / iBC) spike (the thesis's
            # "data spikes"); a symmetric log scale shows the spikes and the decisive values near 0.
            right.set_yscale("symlog", linthresh=1.0)
        right.set(ylabel=what)
        goals_axis = right.twinx()
        for n in range(1, count + 1):
            goals_axis.step(tsk["time"], tsk[f"T{n}count"], where="post", color=TASK_COLOURS[(n - 1) % len(TASK_COLOURS)],
                            linestyle=":", linewidth=2, label=f"T{n} goals")
        goals_axis.set(ylabel="goals issued")
        right.set_title("Task weights and goals" if scenario.dispatcher != "optimal" else "Assignment costs and goals")
        _legend(right, goals_axis)
    right.set_xlabel("time (s)")
    right.grid(alpha=0.3)
    figure.suptitle(scenario.title, fontsize="medium")
    figure.tight_layout()
    figure.savefig(path, dpi=100, metadata=PNG_METADATA)


def _legend(axis: Any, twin: Any) -> None:
    handles, labels = axis.get_legend_handles_labels()
    more_handles, more_labels = twin.get_legend_handles_labels()
    axis.legend(handles + more_handles, labels + more_labels, loc="upper left", fontsize="small", ncols=2)


def draw_paths(scenario: Scenario, recorder: Recorder, path: Path, grid: Any = None) -> None:
    """x/y of every robot over the map (occupied cells dark), stations marked."""
    xy = _columns(recorder.xy_header, recorder.xy)
    figure = Figure(figsize=(12, 5.2))
    axis = figure.subplots()
    if grid is not None:
        width, height = grid.width * grid.resolution, grid.height * grid.resolution
        axis.imshow(grid.occupied, origin="lower", cmap="Greys", vmin=0, vmax=1.6, interpolation="nearest",
                    extent=(grid.origin_x, grid.origin_x + width, grid.origin_y, grid.origin_y + height))
    for index, robot in enumerate(scenario.robots):
        colour = ROBOT_COLOURS[index % len(ROBOT_COLOURS)]
        axis.plot(xy[f"{robot.id}_x"], xy[f"{robot.id}_y"], color=colour, linewidth=1.4, alpha=0.8, label=robot.id)
        axis.plot(*robot.start[:2], marker="o", color=colour, markersize=6)
    for n, task in enumerate(scenario.tasks, 1):
        colour = TASK_COLOURS[(n - 1) % len(TASK_COLOURS)]
        axis.plot(*task.source, marker="s", markersize=10, color=colour, markeredgecolor="black")
        axis.plot(*task.destination, marker="^", markersize=11, color=colour, markeredgecolor="black")
        axis.annotate(f"T{n} source", task.source, textcoords="offset points", xytext=(8, 6), fontsize="small")
        axis.annotate(f"T{n} destination", task.destination, textcoords="offset points", xytext=(8, -12), fontsize="small")
    if grid is None:
        axis.set(xlim=(0, FLOOR_M[0]), ylim=(0, FLOOR_M[1]))
    axis.set(title=f"Robot x-y positions: {scenario.title}", xlabel="x (m)", ylabel="y (m)", aspect="equal")
    axis.legend(loc="upper right", fontsize="small")
    axis.grid(alpha=0.2)
    figure.tight_layout()
    figure.savefig(path, dpi=100, metadata=PNG_METADATA)
