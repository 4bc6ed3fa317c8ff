"""`softplc alarms ...` against a running runtime over OPC UA: by role, with clear refusals, and the journal export."""

from __future__ import annotations

import asyncio
import csv
import io

import pytest

from softplc.app.cli import main
from tests.alarms_support import DRIVER, plant, running_alarm_plant
from tests.opcua_support import PASSWORDS

ALARMS = """
definitions:
  - {name: level_hi, limit: {tag: level, hi: 90}, priority: high, message: "level {value:.0f} m"}
  - {name: nav_failed, discrete: {tag: navstate, value: failed}}
"""


async def softplc(capsys, monkeypatch, endpoint: str, *argv: str, user: str | None = None) -> tuple[int, str, str]:
    """Run the command line in a thread (it has its own event loop) beside the running plant."""
    if user is not None:
        monkeypatch.setenv("SOFTPLC_PASSWORD", PASSWORDS[user])
        argv = (*argv, "--user", user)
    code = await asyncio.to_thread(main, [*argv, "--endpoint", endpoint])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


async def _active(runtime) -> None:
    runtime.db.submit([("level", 95.0), ("navstate", "failed")], DRIVER)
    for _ in range(300):
        if runtime.db.value("_sys.alarms.unacknowledged") == 2:
            return
        await asyncio.sleep(0.01)
    raise AssertionError("the alarms did not become active")


async def test_a_viewer_lists_but_may_not_acknowledge_and_is_told_why(tmp_path, capsys, monkeypatch) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        await _active(runtime)
        code, out, err = await softplc(capsys, monkeypatch, server.endpoint, "alarms", "list")
        assert code == 0, err
        assert out.splitlines()[0].split() == ["alarm", "state", "priority", "since", "message"]
        assert "level_hi" in out and "unacknowledged" in out and "level 95 m" in out
        code, out, err = await softplc(capsys, monkeypatch, server.endpoint, "alarms", "ack", "level_hi", user="viewer")
        assert code == 4  # not allowed, as for every OPC UA client command
        assert "refused: alarms.acknowledge needs the operator role or higher, and user 'viewer' does not have it" in err
        code, _, err = await softplc(capsys, monkeypatch, server.endpoint, "alarms", "ack", "level_hi")
        assert code == 4 and "an anonymous session (a viewer)" in err
        assert runtime.db.value("_sys.alarms.unacknowledged") == 2


async def test_an_operator_acknowledges_shelves_comments_and_exports_the_journal(tmp_path, capsys, monkeypatch) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        await _active(runtime)
        endpoint = server.endpoint
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "ack", "level_hi", "--comment", "pump checked", user="operator")
        assert (code, out.strip()) == (0, "acknowledged level_hi (now acknowledged)"), err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "ack", "level_hj", user="operator")
        assert code == 1 and "refused: no alarm named 'level_hj' (did you mean 'level_hi'?)" in err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "shelve", "nav_failed", "--for", "30min",
                                       "--reason", "robot in repair", user="operator")
        assert code == 0 and out.startswith("shelved nav_failed for 30 min"), err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "shelve", "level_hi", "--for", "3d",
                                       "--reason", "x", user="operator")
        assert code == 1 and "bad duration '3d'" in err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "comment", "nav_failed", "wheel ordered", user="operator")
        assert code == 0, err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "unshelve", "nav_failed", user="operator")
        assert code == 0 and "unshelved nav_failed (now unacknowledged)" in out
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "out-of-service", "nav_failed", "--reason", "x", user="operator")
        assert code == 4 and "needs the engineer role" in err
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "ack", "--all", user="operator")
        assert code == 0 and "acknowledged 1 alarm(s): nav_failed" in out
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "list", "--state", "unacknowledged")
        assert code == 0 and "no alarms (unacknowledged)" in err

        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "journal", "--export", "csv")
        assert code == 0, err
        rows = list(csv.DictReader(io.StringIO(out)))
        assert [(row["alarm"], row["transition"], row["user"]) for row in rows] == [
            ("nav_failed", "acknowledged", "operator"), ("nav_failed", "unshelved", "operator"), ("nav_failed", "commented", "operator"),
            ("nav_failed", "shelved", "operator"), ("level_hi", "acknowledged", "operator"),
            ("nav_failed", "activated", ""), ("level_hi", "activated", "")]
        assert next(row for row in rows if row["transition"] == "shelved")["comment"] == "robot in repair"
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "journal", "--alarm", "level_*", "--by", "operator")
        assert code == 0 and out.count("level_hi") == 1 and "pump checked" in out
        target = tmp_path / "journal.csv"
        code, out, err = await softplc(capsys, monkeypatch, endpoint, "alarms", "journal", "--since", "1h", "--export", "csv", "--out", str(target))
        assert code == 0 and f"wrote 7 journal rows to {target}" in err and len(target.read_text().splitlines()) == 8


async def test_an_unreachable_runtime_is_said_plainly(tmp_path, capsys, monkeypatch) -> None:
    code, out, err = await softplc(capsys, monkeypatch, "opc.tcp://127.0.0.1:9/softplc/", "alarms", "list")
    assert code == 3 and "softplc alarms: cannot connect to opc.tcp://127.0.0.1:9/softplc/" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("argv", [["alarms", "ack"], ["alarms", "ack", "x", "--all"]])
def test_ack_needs_names_or_all(argv, capsys) -> None:
    assert main([*argv, "--endpoint", "opc.tcp://127.0.0.1:9/"]) == 2
    assert "name the alarms to acknowledge, or give --all" in capsys.readouterr().err


async def test_the_endpoint_comes_from_the_plant_configuration_with_the_shared_login_options(tmp_path, capsys, monkeypatch) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        await _active(runtime)
        config = tmp_path / "where.yaml"
        config.write_text(f"servers:\n  opcua:\n    endpoint: {server.endpoint}\n")
        monkeypatch.setattr("sys.stdin", io.StringIO(PASSWORDS["operator"] + "\n"))
        argv = ["alarms", "ack", "level_hi", "--config", str(config), "--user", "operator", "--password-stdin"]  # no --endpoint
        code = await asyncio.to_thread(main, argv)
        assert (code, capsys.readouterr().out.strip()) == (0, "acknowledged level_hi (now acknowledged)")


@pytest.mark.parametrize(("options", "message"), [
    (["--certificate", "c.der"], "give --certificate and --key together"),
    (["--certificate", "c.der", "--key", "k.pem"], "--certificate and --key are for --security Sign or SignAndEncrypt"),
    (["--password-stdin"], "--password-stdin needs --user NAME"),
])
def test_contradicting_login_options_are_a_usage_error(options, message, capsys) -> None:
    assert main(["alarms", "list", *options, "--endpoint", "opc.tcp://127.0.0.1:9/"]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("subcommand", ["list", "ack", "shelve", "unshelve", "comment", "out-of-service", "in-service", "journal"])
def test_every_subcommand_teaches_by_example(subcommand, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["alarms", subcommand, "--help"])
    out = capsys.readouterr().out
    assert f"softplc alarms {subcommand} " in out.split("Example", 1)[1].replace("\n", " ")
    assert "--password-stdin" in out and "--security MODE[,CERT,KEY]" in out and "--config FILE" in out
