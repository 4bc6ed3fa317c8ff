"""The OPC UA parts of the command line and configuration: `softplc users`, `softplc opcua`,
`softplc run` flags and messages, and clear errors for bad settings, users files and busy ports."""

from __future__ import annotations

import asyncio
import io
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from asyncua import Client, ua

from softplc.adapters.opcua import OpcUaServer, OpcUaSettings, UserStore
from softplc.adapters.opcua.settings import SettingsError
from softplc.app.cli import main
from softplc.app.runtime import AdapterError, Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.security.users import verify_password
from tests.conftest import REPO
from tests.opcua_support import PLANT, write_config

SMALL = """
version: 1
plant: {name: cli-test}
tags:
  speed: {type: float64, unit: m/s, min: 0, max: 2}
servers:
  opcua:
    endpoint: opc.tcp://127.0.0.1:0/softplc/
    security: [None]
"""


def softplc(*arguments: str, cwd: Path, stdin: str | None = None, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """`softplc ARGUMENTS` in its own process."""
    return subprocess.run(
        [sys.executable, "-m", "softplc.app.cli", *arguments], cwd=cwd, input=stdin, capture_output=True, text=True,
        timeout=timeout, env=dict(os.environ, PYTHONPATH=str(REPO)),
    )


def cli(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, *arguments: str, stdin: str = "") -> tuple[int, str, str]:
    """`softplc ARGUMENTS` in this process (faster; same parser and commands)."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(stdin))
    try:
        code = main(list(arguments))
    except SystemExit as stop:  # as the interpreter would: a message goes to stderr, exit 1
        if isinstance(stop.code, str):
            print(stop.code, file=sys.stderr)
        code = stop.code if isinstance(stop.code, int) else 1
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_users_add_list_remove(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "tagdb.yaml").write_text(SMALL)
    code, out, err = cli(capsys, monkeypatch, "users", "add", "alice", "--role", "operator", "--password-stdin", stdin="correct horse\n")
    assert code == 0, err
    assert "added user 'alice' (operator, password)" in out
    users_file = tmp_path / ".softplc" / "users.yaml"
    assert users_file.stat().st_mode & 0o077 == 0
    entry = UserStore(users_file).get("alice")
    assert entry is not None and entry.password_hash.startswith("scrypt$") and "correct horse" not in users_file.read_text()
    assert verify_password("correct horse", entry.password_hash) and not verify_password("wrong horse", entry.password_hash)
    code, out, _ = cli(capsys, monkeypatch, "users", "list")
    assert code == 0 and "alice" in out and "operator" in out
    code, _, err = cli(capsys, monkeypatch, "users", "add", "bob", "--role", "viewer", "--password-stdin", stdin="short\n")
    assert code == 1 and "at least 8 characters" in err
    code, _, err = cli(capsys, monkeypatch, "users", "add", "bob", "--role", "admin", "--password-stdin", stdin="long enough\n")
    assert code == 2 and "invalid choice" in err
    code, _, err = cli(capsys, monkeypatch, "users", "add", "bob", "--role", "viewer", stdin="")
    assert code == 1 and "--password-stdin" in err
    code, _, _ = cli(capsys, monkeypatch, "users", "remove", "alice")
    assert code == 0 and UserStore(users_file).get("alice") is None
    code, _, err = cli(capsys, monkeypatch, "users", "remove", "alice")
    assert code == 1 and "no user 'alice'" in err


def test_broken_users_file_is_reported_with_its_location(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "tagdb.yaml").write_text(SMALL)
    users_file = tmp_path / ".softplc" / "users.yaml"
    users_file.parent.mkdir()
    users_file.write_text("users:\n  alice: {role: root, password: x}\n")
    code, _, err = cli(capsys, monkeypatch, "users", "list")
    assert code == 2
    assert ".softplc/users.yaml:2:17: user 'alice': role must be one of viewer, operator, engineer" in err


async def test_runtime_refuses_to_start_on_a_broken_users_file_or_a_busy_port(tmp_path: Path) -> None:
    config = load_config(write_config(tmp_path, PLANT))
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "users.yaml").write_text("users: [alice]\n")
    runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
    runtime.add_adapter(OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/x/", security=("None",))))
    with pytest.raises(AdapterError, match="users file is invalid"):
        await runtime.start()
    (tmp_path / "state" / "users.yaml").unlink()
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        runtime = Runtime(config, RealClock(), state_dir=tmp_path / "state")
        runtime.add_adapter(OpcUaServer(OpcUaSettings(endpoint=f"opc.tcp://127.0.0.1:{port}/x/", security=("None",))))
        with pytest.raises(AdapterError, match=f"cannot listen on 127.0.0.1:{port}"):
            await runtime.start()


def test_settings_defaults_depend_on_the_bind_address() -> None:
    loopback = OpcUaSettings()
    assert loopback.policies == ("None", "Basic256Sha256_Sign", "Basic256Sha256_SignAndEncrypt")
    assert loopback.anonymous_role is not None
    exposed = OpcUaSettings(endpoint="opc.tcp://0.0.0.0:4840/softplc/")
    assert exposed.policies == ("Basic256Sha256_Sign", "Basic256Sha256_SignAndEncrypt") and exposed.anonymous_role is None
    assert OpcUaSettings(endpoint="opc.tcp://0.0.0.0:4840/", security=("None",), anonymous="viewer").policies == ("None",)
    for bad, key in ((dict(endpoint="http://x:1/"), "endpoint"), (dict(security=("Basic128",)), "security"), (dict(anonymous="operator"), "anonymous")):
        with pytest.raises(SettingsError) as error:
            OpcUaSettings(**bad)
        assert error.value.key == key


def test_run_reports_bad_settings_clearly(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "tagdb.yaml").write_text(SMALL)
    code, _, err = cli(capsys, monkeypatch, "run", "--opcua-security", "None,Basic128", "--no-modbus")
    assert code != 0 and "--opcua-security" in err and "unknown security policy 'Basic128'" in err
    (tmp_path / "broken.yaml").write_text(SMALL.replace("opc.tcp://127.0.0.1:0/softplc/", "tcp://nowhere"))
    code, _, err = cli(capsys, monkeypatch, "run", "broken.yaml", "--no-modbus")
    assert code == 2 and "broken.yaml:8:15: endpoint must look like opc.tcp://HOST:PORT/PATH" in err
    code, _, err = cli(capsys, monkeypatch, "run", "--no-opcua", "--no-modbus", "--no-hmi", "--no-audit", "--duration", "0.2", "--no-status")
    assert code == 0 and "serving: nothing" in err


def test_run_serves_with_command_line_overrides(tmp_path: Path) -> None:
    (tmp_path / "tagdb.yaml").write_text(SMALL.replace("    security: [None]\n", "    security: [Basic256Sha256_Sign]\n"))

    process = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "run", "--opcua-security", "None", "--opcua-anonymous", "viewer", "--no-modbus", "--no-status"],
        cwd=tmp_path, stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)),
    )
    try:
        assert process.stderr is not None
        line = ""
        while not line.startswith("serving: OPC UA on "):
            line = process.stderr.readline()
            assert line, "softplc run ended before serving"
        assert "security: None;" in line and "anonymous read-only" in line
        endpoint = line.split()[4]

        async def read() -> float:
            async with Client(endpoint, timeout=10) as client:
                ns = await client.get_namespace_index("urn:softplc:tags")
                return await client.get_node(ua.NodeId("speed", ns)).read_value()

        assert asyncio.run(read()) == 0.0
    finally:
        process.terminate()
        process.wait(timeout=30)


# Every client command that reaches a runtime over OPC UA, with what else it needs on its command line.
CLIENT_COMMANDS = {
    "read": ["read", "speed"],
    "write": ["write", "speed=1"],
    "watch": ["watch", "speed"],
    "forces": ["forces"],
    "force": ["force", "speed=1"],
    "unforce": ["unforce", "speed"],
    "alarms": ["alarms", "list"],
    "audit": ["audit"],
    "apply": ["apply"],
    "robot-agent": ["robot-agent", "--robot", "r01"],
}


@pytest.mark.parametrize("command", list(CLIENT_COMMANDS))
@pytest.mark.parametrize("endpoint, hint", [
    ("http://127.0.0.1:8080/", "http:// is the address of a web page (the HMI), not of an OPC UA server"),
    ("127.0.0.1:4840", "no scheme"),
    ("opc.tcp://", "no host"),
    ("opc.tcp://plc7:port/softplc/", "'port' is not a port number"),
], ids=["http", "no scheme", "no host", "bad port"])
def test_client_commands_refuse_an_endpoint_that_is_not_opc_tcp(command: str, endpoint: str, hint: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit:
        main([*CLIENT_COMMANDS[command], "--endpoint", endpoint])
    assert exit.value.code == 2  # a bad command line
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"argument --endpoint: {endpoint!r} is not an OPC UA endpoint ({hint}): write opc.tcp://HOST:PORT/PATH, e.g. opc.tcp://127.0.0.1:4840/softplc/" in err, err
