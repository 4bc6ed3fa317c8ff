"""A remote robot agent in its own process drives a robot over OPC UA, survives a runtime restart,
and its tags are BAD while it is away."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from urllib.parse import urlparse

import pytest
from conftest import REPO
from fleet_support import robot_yaml, write_plant

from softplc.adapters.fleet.adapter import FleetAdapter
from softplc.adapters.opcua import OpcUaServer, OpcUaSettings, Role, UserStore
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.tags import Quality
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import load_robots

MAP = REPO / "robots" / "maps" / "factory.yaml"
PASSWORD = "robot-pass-123"


async def wait_for(condition: Callable[[], bool], timeout: float, what: str) -> float:
    """Poll every 10 ms until `condition()` holds; fail with `what` after `timeout` seconds."""
    start = time.monotonic()
    while not condition():
        if time.monotonic() - start > timeout:
            raise AssertionError(f"timed out after {timeout} s waiting for: {what}")
        await asyncio.sleep(0.01)
    return time.monotonic() - start


async def start_runtime(tagdb: Path, endpoint: str) -> tuple[Runtime, OpcUaServer, FleetAdapter]:
    config = load_config(tagdb)
    runtime = Runtime(config, RealClock(), state_dir=tagdb.parent / "state")
    server = OpcUaServer(OpcUaSettings(endpoint=endpoint))
    fleet = FleetAdapter(load_robots(tagdb.parent / "robots.yaml"), load_map(MAP), heartbeat_timeout=1.0)
    runtime.add_adapter(fleet)
    runtime.add_adapter(server)
    await runtime.start()
    return runtime, server, fleet


def arrived(runtime: Runtime, robot: str, x: float, y: float) -> bool:
    db = runtime.db
    return (db.value(f"{robot}_navstate") == "arrived" and not db.value(f"{robot}_status")
            and abs(db.value(f"{robot}_xpos") - x) < 0.5 and abs(db.value(f"{robot}_ypos") - y) < 0.5)


@pytest.fixture
def plant(tmp_path: Path) -> Path:
    tagdb = write_plant(tmp_path, [robot_yaml("r01", 7.925, 5.925, driver="remote"), robot_yaml("r02", 7.925, 2.925)])
    (tmp_path / "state").mkdir()
    UserStore(tmp_path / "state" / "users.yaml").add("r01", Role.OPERATOR, PASSWORD)
    return tagdb


async def test_remote_agent_registers_moves_survives_restart_and_goes_bad_when_gone(plant: Path) -> None:
    runtime, server, fleet = await start_runtime(plant, "opc.tcp://127.0.0.1:0/softplc/")
    db = runtime.db
    # Before any agent connected, the remote robot's published tags are BAD.
    await wait_for(lambda: db["r01_xpos"].quality is Quality.BAD, 2, "r01 tags BAD before the agent connects")
    env = dict(os.environ, PYTHONPATH=str(REPO), SOFTPLC_PASSWORD=PASSWORD)
    agent = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "robot-agent", "--endpoint", server.endpoint, "--robot", "r01",
         "--robots", str(plant.parent / "robots.yaml"), "--map", str(MAP), "--user", "r01"],
        cwd=plant.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        await wait_for(lambda: db.value("r01_online"), 30, "the agent to register and report")
        assert db["r01_xpos"].quality is Quality.GOOD
        registration = fleet.remotes["r01"].registration
        assert registration is not None and registration.host == socket.gethostname() and registration.pid == agent.pid
        assert "gripper" in registration.hardware

        # It drives to a goal written to its tags, and clears its status there.
        db.submit([("r01_xgoal", 8.925), ("r01_ygoal", 5.925), ("r01_status", True)], "test")
        await wait_for(lambda: db.value("r01_navstate") == "moving", 5, "r01 moving")
        await wait_for(lambda: arrived(runtime, "r01", 8.925, 5.925), 30, "r01 at (8.925, 5.925)")
        before_restart = db.value("r01_xpos")

        # The runtime restarts on the same port; the agent reconnects with backoff.
        port = urlparse(server.endpoint).port
        await runtime.stop()
        runtime, server, fleet = await start_runtime(plant, f"opc.tcp://127.0.0.1:{port}/softplc/")
        db = runtime.db
        await wait_for(lambda: db["r01_xpos"].quality is Quality.BAD, 2, "r01 tags BAD while the agent is away")
        assert not db.value("r01_online")
        await wait_for(lambda: db.value("r01_online"), 30, "the agent to reconnect")
        await wait_for(lambda: db["r01_xpos"].quality is Quality.GOOD, 2, "r01 tags GOOD again")
        # The robot stayed where it was: its pose comes from the agent, not the restarted tags.
        assert abs(db.value("r01_xpos") - before_restart) < 0.3
        db.submit([("r01_xgoal", 8.925), ("r01_ygoal", 4.925), ("r01_status", True)], "test")
        await wait_for(lambda: arrived(runtime, "r01", 8.925, 4.925), 40, "r01 at (8.925, 4.925) after the restart")

        # The agent dies: after the heartbeat timeout its tags go BAD and it is offline.
        agent.send_signal(signal.SIGKILL)
        agent.wait(10)
        waited = await wait_for(lambda: db["r01_xpos"].quality is Quality.BAD, 5, "r01 tags BAD after the agent died")
        assert waited > 0.5  # not at once: only after the heartbeat timeout (1 s)
        assert not db.value("r01_online")
        assert db["r02_xpos"].quality is Quality.GOOD  # the simulated robot is unaffected
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait(10)
        await runtime.stop()
        output = agent.stdout.read() if agent.stdout else ""
        print(output[-3000:])


def make_certificate(directory: Path, name: str) -> tuple[Path, Path, bytes]:
    """A self-signed OPC UA client certificate (DER) and its key (PEM)."""
    from asyncua.crypto.cert_gen import (
        dump_private_key_as_pem,
        generate_private_key,
        generate_self_signed_app_certificate,
    )
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = generate_private_key()
    certificate = generate_self_signed_app_certificate(
        key, name, {}, [x509.UniformResourceIdentifier(f"urn:softplc:robot:{name}"), x509.DNSName("localhost")],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH], days=30,
    )
    der = certificate.public_bytes(serialization.Encoding.DER)
    (directory / f"{name}.der").write_bytes(der)
    (directory / f"{name}.key.pem").write_bytes(dump_private_key_as_pem(key))
    return directory / f"{name}.der", directory / f"{name}.key.pem", der


async def test_remote_agent_logs_in_with_its_certificate_over_an_encrypted_channel(plant: Path) -> None:
    from softplc.adapters.opcua import Pki
    from softplc.security.certificates import fingerprint

    state = plant.parent / "state"
    certificate, key, der = make_certificate(plant.parent, "r01")
    Pki(state / "pki").trust(str(certificate))
    UserStore(state / "users.yaml").add("r01", Role.OPERATOR, certificate=fingerprint(der))
    config = load_config(plant)
    runtime = Runtime(config, RealClock(), state_dir=state)
    server = OpcUaServer(OpcUaSettings(endpoint="opc.tcp://127.0.0.1:0/softplc/", security=("Basic256Sha256_SignAndEncrypt",), anonymous="off"))
    runtime.add_adapter(FleetAdapter(load_robots(plant.parent / "robots.yaml"), load_map(MAP), heartbeat_timeout=1.0))
    runtime.add_adapter(server)
    await runtime.start()
    agent = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "robot-agent", "--endpoint", server.endpoint, "--robot", "r01",
         "--robots", str(plant.parent / "robots.yaml"), "--map", str(MAP), "--certificate", str(certificate), "--private-key", str(key)],
        cwd=plant.parent, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        db = runtime.db
        await wait_for(lambda: db.value("r01_online"), 30, "the agent to log in with its certificate and report")
        db.submit([("r01_xgoal", 7.925), ("r01_ygoal", 6.625), ("r01_status", True)], "test")
        await wait_for(lambda: arrived(runtime, "r01", 7.925, 6.625), 30, "r01 at (7.925, 6.625)")
    finally:
        agent.kill()
        agent.wait(10)
        await runtime.stop()
        print((agent.stdout.read() if agent.stdout else "")[-3000:])


def start_agent(plant: Path, endpoint: str, robot: str, password: str | None = PASSWORD) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    login = []
    if password is not None:
        env["SOFTPLC_PASSWORD"] = password
        login = ["--user", "r01"]
    return subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "robot-agent", "--endpoint", endpoint, "--robot", robot,
         "--robots", str(plant.parent / "robots.yaml"), "--map", str(MAP), *login],
        cwd=plant.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )


async def wait_exit(process: subprocess.Popen[str], timeout: float) -> tuple[int, str]:
    """Let the runtime keep running while the agent process ends; its exit status and output."""
    await wait_for(lambda: process.poll() is not None, timeout, "the agent to exit")
    return process.returncode, process.stdout.read() if process.stdout else ""


async def test_an_agent_for_a_robot_the_runtime_drives_itself_is_refused(plant: Path, caplog: pytest.LogCaptureFixture) -> None:
    runtime, server, fleet = await start_runtime(plant, "opc.tcp://127.0.0.1:0/softplc/")
    agents: list[subprocess.Popen[str]] = []
    try:
        db = runtime.db
        for _ in range(2):  # a second attempt is refused too, and not logged again
            agents.append(start_agent(plant, server.endpoint, "r02"))
            status, output = await wait_exit(agents[-1], 30)
            assert status == 1, output
            assert "refused robot r02: the runtime drives robot r02 itself (driver: sim in" in output
            assert "declare it 'driver: remote' there" in output and "Traceback" not in output
        assert fleet.refusals["r02"].refused == 2
        lines = [r for r in caplog.records if r.name == "softplc.adapters.fleet.remote" and "refused a robot agent" in r.getMessage()]
        assert len(lines) == 1 and lines[0].levelname == "ERROR"
        assert db.value("r02_report") == ""  # the refused agent never drove (it would report every cycle)
        # the runtime's own r02 still drives
        db.submit([("r02_xgoal", 8.925), ("r02_ygoal", 2.925), ("r02_status", True)], "test")
        await wait_for(lambda: arrived(runtime, "r02", 8.925, 2.925), 30, "r02 at (8.925, 2.925)")
    finally:
        for agent in agents:
            if agent.poll() is None:
                agent.kill()
                agent.wait(10)
        await runtime.stop()


async def test_a_wrong_password_is_an_error_and_the_agent_gives_up(plant: Path) -> None:
    runtime, server, _ = await start_runtime(plant, "opc.tcp://127.0.0.1:0/softplc/")
    agent = start_agent(plant, server.endpoint, "r01", password="not-the-password")
    try:
        status, output = await wait_exit(agent, 60)
        assert status == 1, output
        assert output.count("ERROR: robot r01:") == 3 and "(try 3 of 3)" in output
        assert "refused the login of user 'r01' 3 times (BadUserAccessDenied): wrong user name or password" in output
        assert "Traceback" not in output and not runtime.db.value("r01_online")
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait(10)
        await runtime.stop()


async def test_sigterm_stops_the_agent_and_says_so(plant: Path) -> None:
    runtime, server, _ = await start_runtime(plant, "opc.tcp://127.0.0.1:0/softplc/")
    agent = start_agent(plant, server.endpoint, "r01")
    try:
        db = runtime.db
        await wait_for(lambda: db.value("r01_online"), 30, "the agent to register and report")
        agent.send_signal(signal.SIGTERM)
        status, output = await wait_exit(agent, 15)
        assert status == 0, output
        assert "robot-agent r01: SIGTERM received, stopping" in output and output.rstrip().endswith("robot-agent r01: stopped")
        await wait_for(lambda: not db.value("r01_online"), 5, "r01 offline after the agent stopped")
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait(10)
        await runtime.stop()
