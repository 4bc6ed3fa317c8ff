"""The malformed-configuration corpus: every file in tests/configs/bad must fail with exactly the
problems its `# expect: LINE:COL: message` header lines announce (`{*}` matches any text)."""

from __future__ import annotations

import logging
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import REPO

from softplc.app.cli import main
from softplc.config import load_config
from softplc.config.yamlsource import ConfigError

BAD = REPO / "tests" / "configs" / "bad"
CORPUS = sorted(BAD.glob("*.yaml"))
EXPECT = re.compile(r"^# expect: (\d+):(\d+): (.+)$")


def expectations(path: Path) -> list[tuple[int, int, str]]:
    """The `# expect:` lines at the top of a corpus file."""
    result = []
    for line in path.read_text().splitlines():
        match = EXPECT.match(line)
        if match is None:
            break
        result.append((int(match.group(1)), int(match.group(2)), match.group(3)))
    return result


def matches(pattern: str, message: str) -> bool:
    """`pattern` equals `message`, where `{*}` in the pattern stands for any text."""
    regex = ".*".join(re.escape(part) for part in pattern.split("{*}"))
    return re.fullmatch(regex, message) is not None


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str]) -> Iterator:
    """Run `softplc ARGS` in-process; returns (exit code, stdout, stderr). Restores logging."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level

    def run(*args: str) -> tuple[int, str, str]:
        code = main(list(args))
        out, err = capsys.readouterr()
        return code, out, err

    yield run
    root.handlers[:] = handlers
    root.setLevel(level)


def test_the_corpus_is_big_enough_and_every_file_announces_its_problems() -> None:
    assert len(CORPUS) >= 30
    for path in CORPUS:
        assert expectations(path), f"{path.name} has no '# expect: LINE:COL: message' header"


@pytest.mark.parametrize("path", CORPUS, ids=[p.stem for p in CORPUS])
def test_bad_config_reports_exact_locations_and_messages(path: Path) -> None:
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    found = [(p.location.line, p.location.column, p.message) for p in caught.value.problems]
    expected = expectations(path)
    assert len(found) == len(expected), f"expected {expected}, found {found}"
    for (line, column, message), (want_line, want_column, pattern) in zip(found, expected):
        assert (line, column) == (want_line, want_column), f"{message!r} at {line}:{column}"
        assert matches(pattern, message), f"{message!r} does not match {pattern!r}"
    for problem in caught.value.problems:
        assert problem.location.file == str(path)


@pytest.mark.parametrize("path", CORPUS, ids=[p.stem for p in CORPUS])
def test_check_and_run_print_file_line_col_and_exit_2(path: Path, cli) -> None:
    expected = expectations(path)
    for command in (["check", str(path)], ["run", str(path), "--sim", "--duration", "1", "--no-status"]):
        code, out, err = cli(*command)
        assert code == 2, command
        assert "Traceback" not in err + out
        lines = err.splitlines()
        assert lines[-1] == f"{len(expected)} problem{'s' if len(expected) != 1 else ''} found"
        for printed, (line, column, pattern) in zip(lines[:-1], expected, strict=True):
            prefix = f"{path}:{line}:{column}: "
            assert printed.startswith(prefix), printed
            assert matches(pattern, printed[len(prefix):])
        assert "softplc 0" not in err, "run must refuse before starting anything"


def test_missing_file(cli, tmp_path: Path) -> None:
    missing = tmp_path / "nowhere.yaml"
    code, out, err = cli("check", str(missing))
    assert code == 2
    assert err.splitlines()[0] == f"{missing}:1:1: file not found"
    code, out, err = cli("run", str(missing), "--sim", "--duration", "1")
    assert code == 2
    assert err.splitlines()[0] == f"{missing}:1:1: file not found"


def test_unreadable_file_is_a_problem_not_a_traceback(cli, tmp_path: Path) -> None:
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    code, _, err = cli("check", str(binary))
    assert code == 2
    assert err.startswith(f"{binary}:1:1: cannot read the file:")


def test_real_command_line_exits_2_without_traceback() -> None:
    # one real process per command (each costs a Python start-up); in-process runs cover the rest
    path = BAD / "several_problems.yaml"
    softplc = Path(sys.executable).parent / "softplc"
    for command in ([str(softplc), "check", str(path)], [str(softplc), "run", str(path), "--sim", "--duration", "1"]):
        result = subprocess.run(command, capture_output=True, text=True, timeout=60, cwd=BAD)
        assert result.returncode == 2, result.stderr
        assert "Traceback" not in result.stderr
        printed = result.stderr.splitlines()[:-1]
        assert len(printed) == len(expectations(path))
        for line, (row, column, _) in zip(printed, expectations(path)):
            assert line.startswith(f"{path}:{row}:{column}: ")


def test_a_program_that_raises_when_created_is_a_located_problem(cli, tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(
        "version: 1\n"
        "tasks:\n"
        "  fast:\n"
        "    interval: 10ms\n"
        "    programs:\n"
        "      - name: mixer\n"
        f"        program: {BAD.parent / 'sample_programs.py'}:BrokenOnCreation\n"
    )
    for command in (["check", str(plant)], ["run", str(plant), "--sim", "--duration", "1", "--no-status", "--state-dir", str(tmp_path)]):
        code, out, err = cli(*command)
        assert code == 2, (command, err)
        assert "Traceback" not in err + out
        assert err.splitlines()[0] == (
            f"{plant}:7:18: program 'mixer' ({BAD.parent / 'sample_programs.py'}:BrokenOnCreation) cannot be created: "
            "ValueError: calibration table missing"
        )


def test_check_reports_the_problems_of_every_adapter_section_at_once(cli, tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(
        "version: 1\n"
        "tags:\n"
        "  a: {type: float32, modbus: {address: 0}}\n"
        "  b: {type: float32, modbus: {address: 1}}\n"
        "servers:\n"
        "  opcua: {endpoint: 'http://wrong/'}\n"
        f"  modbus: {{host: 'not a host'}}\n"
        "fleet:\n"
        f"  robots: nowhere/robots.yaml\n"
        f"  map: {REPO / 'robots' / 'maps' / 'factory.yaml'}\n"
    )
    code, _, err = cli("check", str(plant))
    assert code == 2, err
    assert sorted(err.splitlines()[:-1]) == sorted([
        f"{plant}:4:40: 'b' (holding registers 1..2) overlaps 'a' (holding registers 0..1, pinned, {plant}:3:40)",
        f"{plant}:6:21: endpoint must look like opc.tcp://HOST:PORT/PATH, not 'http://wrong/'",
        f"{plant}:7:18: bad host 'not a host': write an IP address (127.0.0.1, 0.0.0.0, ::1) or a host name",
        f"{plant}:9:11: robots file not found: {tmp_path / 'nowhere' / 'robots.yaml'}",
    ])


def test_pinned_modbus_addresses_are_checked_while_the_server_is_off(cli, tmp_path: Path) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text("version: 1\ntags:\n  a: {type: float32, modbus: {address: 0}}\n  b: {type: float32, modbus: {address: 1}}\n")
    code, _, err = cli("check", str(plant))
    assert code == 2 and "'b' (holding registers 1..2) overlaps 'a'" in err, err
