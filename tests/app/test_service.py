"""contrib/softplc.service: a valid systemd unit whose ExecStart is a `softplc run` command line softplc accepts."""

from __future__ import annotations

import configparser
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from tools_support import missing

from softplc.app.cli import build_parser, cmd_run
from tests.conftest import REPO

UNIT = REPO / "contrib" / "softplc.service"
INSTALLED = "/opt/softplc/.venv/bin/softplc"


def unit() -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=True, interpolation=None, comment_prefixes=("#", ";"))
    parser.optionxform = str  # systemd keys are case-sensitive
    parser.read_string(UNIT.read_text())
    return parser


def test_systemd_analyze_verifies_the_unit(tmp_path: Path) -> None:
    if shutil.which("systemd-analyze") is None:
        missing("systemd-analyze is not installed (Debian's systemd package; scripts/install-test-tools.sh)")
    # verify checks that ExecStart's program exists: point it at this checkout's softplc.
    installed = tmp_path / "softplc.service"
    installed.write_text(UNIT.read_text().replace(INSTALLED, str(Path(sys.executable).parent / "softplc")))
    result = subprocess.run(["systemd-analyze", "verify", str(installed)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stderr == "", result.stderr  # not even a warning (an unknown key is one)


def test_the_unit_has_what_the_docs_promise() -> None:
    service = unit()["Service"]
    assert service["User"] == "softplc" and service["StateDirectory"] == "softplc"
    assert service["KillSignal"] == "SIGTERM" and service["KillMode"] == "mixed"
    assert service["Restart"] == "on-failure"
    assert service["RestartPreventExitStatus"].split() == ["2", "3"]
    assert unit()["Install"]["WantedBy"] == "multi-user.target"


def test_exec_start_is_a_softplc_run_command_line_that_parses() -> None:
    argv = shlex.split(unit()["Service"]["ExecStart"])
    assert argv[0] == INSTALLED and argv[1] == "run"
    args = build_parser().parse_args(argv[1:])  # an unknown or malformed option would exit here
    assert args.func is cmd_run
    assert str(args.config) == "/etc/softplc/tagdb.yaml" and str(args.state_dir) == "/var/lib/softplc"
    assert args.state_dir.name == unit()["Service"]["StateDirectory"]
    help_text = subprocess.run([sys.executable, "-m", "softplc.app.cli", "run", "--help"], capture_output=True, text=True,
                               timeout=60, cwd=REPO).stdout
    for option in (word.split("=")[0] for word in argv[2:] if word.startswith("--")):
        assert option in help_text


def test_operations_doc_shows_the_unit_as_it_is() -> None:
    doc = (REPO / "docs" / "operations.md").read_text()
    body = "[Unit]" + UNIT.read_text().split("[Unit]", 1)[1]  # the unit without its header comment
    assert f"```ini\n{body}```" in doc
