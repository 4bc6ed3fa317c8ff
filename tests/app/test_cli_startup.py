"""Starting the command line stays cheap: --help never imports the heavy libraries.

Building the parser imports every command module; those must leave asyncua, numpy, scikit-learn
and the like to the functions that run a command. Each test runs softplc in a fresh interpreter
and looks at what it imported.
"""

from __future__ import annotations

import argparse
import importlib
import json
import subprocess
import sys
from collections.abc import Iterator

import pytest
from conftest import REPO

from softplc.app.cli import build_parser

HEAVY = ("asyncua", "pymodbus", "numpy", "scipy", "sklearn", "matplotlib", "jsonschema")

# Runs softplc.app.cli.main once per command line given as JSON in argv[1]; prints, per command
# line, the heavy modules it imported first (modules accumulate over the calls, so a module is
# charged to the first command that needed it), and the exit code.
SCRIPT = """
import contextlib, io, json, sys
from softplc.app.cli import main

heavy = set(sys.argv[2].split(","))
seen = set()
report = []
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exit:
            code = exit.code
    loaded = {name.split(".")[0] for name in sys.modules} & heavy
    report.append({"argv": argv, "exit": code, "imported": sorted(loaded - seen), "modules": sorted(sys.modules)})
    seen |= loaded
print(json.dumps(report))
"""


def run_softplc(*argvs: list[str]) -> list[dict]:  # type: ignore[type-arg]
    """Run each argv through softplc.app.cli.main in one fresh interpreter; what each imported."""
    result = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps(argvs), ",".join(HEAVY)],
        capture_output=True, text=True, cwd=REPO, timeout=120, check=False,
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def command_paths(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Every command and subcommand of the parser, e.g. ('scenario',), ('scenario', 'run')."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, subparser in action.choices.items():
                yield (*prefix, name)
                yield from command_paths(subparser, (*prefix, name))


def test_help_of_every_command_imports_no_heavy_library() -> None:
    commands = list(command_paths(build_parser()))
    assert ("latency",) in commands and ("robot-agent",) in commands and ("scenario", "run") in commands
    report = run_softplc(["--help"], *[[*command, "--help"] for command in commands])
    for run in report:
        assert run["exit"] == 0, f"softplc {' '.join(run['argv'])} exited {run['exit']}"
        assert not run["imported"], f"softplc {' '.join(run['argv'])} imported {', '.join(run['imported'])}"


def test_check_imports_what_the_adapters_need_and_no_more() -> None:
    # Building the adapters (what check does) needs asyncua, pymodbus, numpy and scipy; the
    # commands that only run something (scenarios, latency, the SVM, the robot agent) stay out.
    (run,) = run_softplc(["check", "tagdb.yaml"])
    assert run["exit"] == 0
    modules = set(run["modules"])
    for unneeded in ("sklearn", "matplotlib", "softplc.scenarios.runner", "softplc.latency.measurement", "softplc.clients.robot_agent.agent"):
        assert unneeded not in modules


def test_choices_copied_for_a_light_parser_match_their_source() -> None:
    from softplc.adapters.opcua import cli as opcua_cli
    from softplc.clients.robot_agent import agent
    from softplc.clients.robot_agent import cli as fleet_cli
    from softplc.core import roles
    assert opcua_cli.ROLE_NAMES == roles.ROLE_NAMES
    assert fleet_cli.AGENT_NAMESPACE == agent.DEFAULT_NAMESPACE


@pytest.mark.parametrize("package", ["softplc", "softplc.adapters.fleet", "softplc.adapters.opcua", "softplc.scenarios"])
def test_packages_export_every_public_name(package: str) -> None:
    module = importlib.import_module(package)
    for name in module.__all__:
        assert getattr(module, name) is not None, name
        assert name in dir(module)
    with pytest.raises(AttributeError):
        module.no_such_name  # noqa: B018
