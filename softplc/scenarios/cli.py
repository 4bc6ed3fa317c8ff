"""`softplc scenario list | run | compare`: the thesis's case studies as reproducible runs."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from softplc.config.yamlsource import ConfigError
from softplc.scenarios.spec import DISPATCHERS, STOPS, builtin_scenarios, find_scenario, load_scenario
from softplc.util.plurals import plural

EXIT_OK, EXIT_FAILURE = 0, 1


def add_commands(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    scenario = subparsers.add_parser(
        "scenario",
        help="run the thesis's case studies (and your own) on the simulated clock",
        description="Scenarios are YAML files of a plant's parameters (tasks, robots, dispatcher). "
        "A run simulates the plant in seconds and writes CSV records, PNG figures and a JSON summary.",
    )
    commands = scenario.add_subparsers(title="scenario commands", metavar="COMMAND")

    listing = commands.add_parser("list", help="list the shipped scenarios", description="List the scenarios shipped in scenarios/.")
    listing.set_defaults(func=cmd_list)

    run = commands.add_parser(
        "run",
        help="run a scenario and write its records, figures and summary",
        description="Run NAME (a shipped scenario, see 'softplc scenario list') or FILE on the simulated clock until "
        "an output storage is full (the thesis's end) or the time limit. Writes XY_/LEV_/TSK_ CSV records, "
        "levels_/xy_ PNG figures, the plant configuration it ran and summary_NAME.json into --out.",
        epilog="Examples: softplc scenario run case1-sim1 | softplc scenario run my.yaml --out runs/my --json | "
        "softplc scenario run case2-sim2 --dispatcher optimal",
    )
    run.add_argument("scenario", help="scenario name or YAML file")
    run.add_argument("--out", type=Path, help="output folder (default runs/NAME)")
    run.add_argument("--json", action="store_true", help="print the JSON summary on stdout instead of a text summary")
    run.add_argument("--progress", action="store_true", help="show the progress bar even when stderr is not a terminal")
    run.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    run.add_argument("--time-limit", type=float, metavar="S", help="override the scenario's time limit (simulated seconds)")
    run.add_argument("--stop", choices=STOPS, help="override when the run ends")
    run.add_argument("--dispatcher", choices=DISPATCHERS, help="run the same plant under another dispatcher")
    run.add_argument("--model", type=Path, help="with --dispatcher svm: the model JSON to use")
    run.set_defaults(func=cmd_run)

    compare = commands.add_parser(
        "compare",
        help="run plants under every dispatcher and tabulate throughput, makespan and idle time",
        description="Run each plant (default: the six thesis scenarios) under each dispatcher that can serve it "
        "and print a Markdown table. By default a run lasts until every output storage is full (makespan).",
    )
    compare.add_argument("scenarios", nargs="*", help="scenario names or files (default: the thesis's six)")
    compare.add_argument("--stop", choices=STOPS, default="all_full", help="when each run ends (default all_full)")
    compare.add_argument("--time-limit", type=float, default=3600.0, metavar="S", help="simulated seconds at most (default 3600)")
    compare.add_argument("--out", type=Path, help="also write every run's records into this folder")
    compare.add_argument("--json", action="store_true", help="print the rows as JSON instead of Markdown")
    compare.set_defaults(func=cmd_compare)


def cmd_list(args: argparse.Namespace) -> int:
    from softplc.util.console import print_table

    rows = []
    for path in builtin_scenarios():
        try:
            scenario = load_scenario(path)
        except ConfigError as error:
            rows.append([path.stem, "?", "?", "?", f"(invalid: {error.problems[0]})"])
            continue
        rows.append([scenario.name, scenario.dispatcher, str(len(scenario.robots)), str(len(scenario.tasks)), scenario.title])
    print_table(rows, ("name", "dispatcher", "robots", "tasks", "title"))
    print("\nrun one with: softplc scenario run NAME   (files in scenarios/; copy one to make your own)")
    return EXIT_OK


def _load(name: str):  # type: ignore[no-untyped-def]
    try:
        return load_scenario(find_scenario(name))
    except FileNotFoundError as error:
        print(f"softplc scenario: {error}", file=sys.stderr)
        return None


def cmd_run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from softplc.app.runtime import AdapterError
    from softplc.scenarios.progress import ProgressBar
    from softplc.scenarios.runner import run_scenario

    scenario = _load(args.scenario)  # a ConfigError reaches main(), which prints FILE:LINE:COL problems
    if scenario is None:
        return EXIT_FAILURE
    if args.dispatcher:
        model = args.model.resolve() if args.model else scenario.model or _default_model()
        if args.dispatcher == "svm" and (model is None or not model.exists()):
            print(f"softplc scenario: no SVM model {model}; give --model FILE.json", file=sys.stderr)
            return EXIT_FAILURE
        scenario = scenario.with_dispatcher(args.dispatcher, model)
    if args.stop:
        scenario = replace(scenario, stop=args.stop)
    out = args.out or Path("runs") / scenario.name
    bar = ProgressBar(scenario.name) if (args.progress or sys.stderr.isatty()) else None
    try:
        result = run_scenario(scenario, out, progress=bar.update if bar else None, figures=not args.no_figures,
                              time_limit=args.time_limit)
    except AdapterError as error:
        print(f"softplc scenario: cannot start: {error}", file=sys.stderr)
        return EXIT_FAILURE
    finally:
        if bar:
            bar.close()
    summary = result.summary
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(text_summary(summary))
        print(f"wrote {', '.join(path.name for path in result.files.values())} to {out}/")
    problems = summary.get("faulted_programs") or summary.get("runtime_error")
    if problems:
        print(f"softplc scenario: the run had problems: {problems}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def text_summary(summary: dict) -> str:  # type: ignore[type-arg]
    lines = [f"{summary['scenario']}: {summary['title']}",
             f"  ended after {summary['sim_duration_s']:.1f} s simulated ({summary['stop_reason']}), "
             f"{summary['wall_time_s']:.2f} s wall time"]
    goals = ", ".join(f"{task} {count}" for task, count in summary["goals_per_task"].items())
    lines.append(f"  goals per task: {goals}")
    for robot, record in summary["robots"].items():
        trips = ", ".join(f"{task} {count}" for task, count in record["trips"].items()) or "none"
        failed = f"; navigation FAILED {plural(record['navigation_failures'], 'time')}" if record["navigation_failures"] else ""
        stuck = f"; stuck {record['stuck_s']:.0f} s (longest {record['longest_stuck_s']:.0f} s)" if record["stuck_s"] >= 0.5 else ""
        lines.append(f"  {robot}: trips {trips}; idle {record['idle_s']:.0f} s{stuck}; utilisation {100 * record['utilisation']:.0f} %{failed}")
    levels = ", ".join(f"{task} in {v['in']:.0f} % / out {v['out']:.0f} %" for task, v in summary["levels_at_end"].items())
    lines.append(f"  levels at the end: {levels}")
    lines.append(f"  throughput {summary['throughput_items_per_min']:.2f} items/min")
    if summary.get("thesis"):
        lines.append(f"  thesis: {summary['thesis']}")
    return "\n".join(lines)


def _default_model() -> Path | None:
    from softplc.scenarios.spec import BUILTIN_DIR

    path = BUILTIN_DIR / "svm" / "case3-sim1-model.json"
    return path if path.exists() else None


def cmd_compare(args: argparse.Namespace) -> int:
    from softplc.scenarios.compare import THESIS_SCENARIOS, compare, markdown_table

    names = args.scenarios or list(THESIS_SCENARIOS)
    scenarios = []
    for name in names:
        scenario = _load(name)
        if scenario is None:
            return EXIT_FAILURE
        scenarios.append(scenario)
    rows = compare(scenarios, stop=args.stop, time_limit=args.time_limit, out_dir=args.out,
                   report=lambda text: print(text, file=sys.stderr))
    print(json.dumps(rows, indent=2) if args.json else markdown_table(rows))
    return EXIT_OK
