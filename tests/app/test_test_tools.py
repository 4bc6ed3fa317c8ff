"""The independent tools the tests drive (Chromium, Prometheus, systemd-analyze, PostgreSQL...):
where one is missing its tests are skipped with how to install it — except under CI (CI=true),
where a missing tool fails the run with that message: a CI run that skipped the browser tests
passed with exit 0 while checking none of them."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO

# Test files that need a tool found on PATH, and the words their refusal contains.
NEEDS = {
    "tests/adapters/hmi/test_hmi_browser.py": "chromium is not installed",
    "tests/adapters/metrics/test_metrics_prometheus.py": "prometheus is not installed",
    "tests/app/test_service.py": "systemd-analyze is not installed",
}


def pytest_without_tools(ci: str | None, *files: str) -> subprocess.CompletedProcess[str]:
    """`files` (default: those of NEEDS) run by pytest in a process whose PATH holds none of the tools."""
    env = {name: value for name, value in os.environ.items() if not name.startswith(("PYTEST_", "CI"))}
    env["PATH"] = str(Path(sys.executable).parent)  # this Python (and the venv's scripts) only
    if ci is not None:
        env["CI"] = ci
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:randomly", "-p", "no:cacheprovider", "-q", "-rs", *(files or NEEDS)],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300,
    )


def test_without_ci_a_missing_tool_skips_its_tests_saying_how_to_install_it() -> None:
    result = pytest_without_tools(None)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    for words in NEEDS.values():
        assert words in output and "scripts/install-test-tools.sh" in output, (words, output)
    assert " failed" not in output and " error" not in output, output


@pytest.mark.parametrize("ci", ["true", "1"])
@pytest.mark.parametrize("file", list(NEEDS))
def test_under_ci_a_missing_tool_fails_the_run_with_a_clear_message(ci: str, file: str) -> None:
    result = pytest_without_tools(ci, file)
    output = result.stdout + result.stderr
    assert result.returncode not in (0, 5), output  # 5: nothing collected
    assert NEEDS[file] in output, output
    assert "under CI (CI=true) every test tool must be installed" in output, output
    assert " skipped" not in output, output


RETRY = REPO / "scripts" / "retry.sh"
# Fails on its first two runs, succeeds on the third: counts its runs in the file `runs`.
FLAKY = 'runs=$(cat runs 2>/dev/null || echo 0); echo $((runs + 1)) > runs; [ "$runs" -ge 2 ]'


def test_retry_runs_a_failing_command_again_with_backoff_until_it_succeeds(tmp_path: Path) -> None:
    started = time.monotonic()
    result = subprocess.run([str(RETRY), "4", "0.2", "bash", "-c", FLAKY], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    waited = time.monotonic() - started
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "runs").read_text().strip() == "3"
    assert result.stderr.splitlines() == [
        "bash -c ... failed (attempt 1 of 4, exit status 1); trying again in 0.2 s",
        "bash -c ... failed (attempt 2 of 4, exit status 1); trying again in 0.4 s",
    ]
    assert waited >= 0.6  # the backoff doubled: 0.2 s, then 0.4 s


def test_retry_gives_up_after_its_attempts_with_the_commands_exit_status(tmp_path: Path) -> None:
    result = subprocess.run([str(RETRY), "2", "0", "bash", "-c", FLAKY + " || exit 7"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert result.returncode == 7
    assert (tmp_path / "runs").read_text().strip() == "2"
    assert result.stderr.splitlines()[-1] == "bash -c ... failed 2 times (exit status 7); giving up"
