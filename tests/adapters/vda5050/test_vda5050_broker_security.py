"""The documented broker setup (contrib/mosquitto: TLS, a password per client, per-vehicle ACLs) on a real mosquitto:
the master and a vehicle work through it, and a vehicle cannot speak for another."""

from __future__ import annotations

import asyncio
import json
import subprocess
from pathlib import Path

import pytest
from conftest import REPO
from mosquitto_server import MosquittoServer, MosquittoUnavailable, free_port
from tools_support import missing
from vda5050_support import MAP, adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.clients.robot_agent.vda5050.agent import VehicleAgent
from softplc.clients.robot_agent.vda5050.vehicle import Vehicle
from softplc.core.clock import RealClock
from softplc.protocols.mqtt import MqttConnection
from softplc.protocols.mqtt_settings import MqttSettings, TlsSettings
from softplc.protocols.vda5050.messages import Headers
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import Pose, load_robots

CONTRIB = REPO / "contrib" / "mosquitto"


def certificates(directory: Path) -> None:
    """A CA and a broker certificate for 127.0.0.1, made with openssl."""
    def openssl(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=directory, check=True, capture_output=True)

    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-subj", "/CN=test ca", "-days", "2")
    openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "broker.key", "-out", "broker.csr", "-subj", "/CN=127.0.0.1")
    (directory / "san.ext").write_text("subjectAltName=IP:127.0.0.1\n")
    openssl("x509", "-req", "-in", "broker.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out", "broker.pem",
            "-days", "2", "-extfile", "san.ext")


def passwords(path: Path, users: dict[str, str]) -> None:
    for index, (user, password) in enumerate(users.items()):
        subprocess.run(["mosquitto_passwd", *(["-c"] if index == 0 else []), "-b", str(path), user, password], check=True, capture_output=True)


@pytest.fixture
def secured(tmp_path: Path):
    """mosquitto with contrib/mosquitto's TLS listener, passwords and ACLs (ACL extended by a second vehicle)."""
    certs = tmp_path / "certs"
    certs.mkdir()
    certificates(certs)
    passwords(tmp_path / "passwords", {"softplc": "master-pw", "acme-F-0042": "vehicle-pw", "acme-F-0043": "other-pw"})
    acl = (CONTRIB / "vda5050.acl").read_text()
    acl += "\n" + acl.split("user acme-F-0042", 1)[1].replace("F-0042", "F-0043").join(["user acme-F-0043", ""])
    (tmp_path / "vda5050.acl").write_text(acl)
    tls_port = free_port()
    config = (CONTRIB / "vda5050.conf").read_text().replace("listener 8883", f"listener {tls_port} 127.0.0.1")
    config = config.replace("/etc/mosquitto/certs", str(certs)).replace("/etc/mosquitto/vda5050.passwords", str(tmp_path / "passwords"))
    config = config.replace("/etc/mosquitto/vda5050.acl", str(tmp_path / "vda5050.acl"))
    import os

    if os.geteuid() == 0:  # mosquitto started as root drops to user mosquitto, who cannot read the test's private folder
        config += "\nuser root\n"
    try:
        server = MosquittoServer(extra=config)
    except MosquittoUnavailable as error:
        missing(str(error))
    server.start()
    try:
        yield server, tls_port, certs / "ca.pem"
    finally:
        server.remove()


def settings(port: int, ca: Path, user: str, password_file: Path) -> MqttSettings:
    return MqttSettings(port=port, client_id=user, username=user, password_file=password_file, tls=TlsSettings(ca_file=ca))


async def test_tls_passwords_and_acls_let_each_vehicle_speak_only_for_itself(tmp_path: Path, secured) -> None:
    server, port, ca = secured
    (tmp_path / "master.pw").write_text("master-pw\n")
    (tmp_path / "vehicle.pw").write_text("vehicle-pw\n")
    plant_dir = tmp_path / "plant"
    plant_dir.mkdir()
    tagdb = write_plant(plant_dir, f"mqtts://127.0.0.1:{port}",
                        [vehicle_yaml("r01", "F-0042", 7.925, 5.925, manufacturer="acme"),
                         vehicle_yaml("r02", "F-0043", 7.925, 2.925, manufacturer="acme")])
    tagdb.write_text(tagdb.read_text().replace("keepalive: 2s}", f"keepalive: 2s, username: softplc, password_file: {tmp_path / 'master.pw'}, "
                                                                 f"tls: {{ca_file: {ca}}}}}"))
    runtime = await start_plant(tagdb)
    db = runtime.db
    robots = load_robots(plant_dir / "robots.yaml")
    vehicle = VehicleAgent(robots["r01"], Floor(load_map(MAP)), settings(port, ca, "acme-F-0042", tmp_path / "vehicle.pw"),
                           clock=RealClock(), state_interval=0.5)
    driving = asyncio.ensure_future(vehicle.run())
    rogue = MqttConnection(settings(port, ca, "acme-F-0042", tmp_path / "vehicle.pw"), "rogue", RealClock())
    roguing = asyncio.ensure_future(rogue.run())
    try:
        await wait_for(lambda: db.value("r01_online") and rogue.connected, 15, "r01 reports through TLS with its password")
        db.submit([("r01_xgoal", 7.925), ("r01_ygoal", 6.6), ("r01_status", True)], "test")
        await wait_for(lambda: db.value("r01_navstate") == "arrived", 30, "an order through the ACLs")
        # r01's credentials publishing r02's state: the broker drops it (ACL); then a bad message on its own topic,
        # which the master does see — so r02's would have arrived before it, had the broker let it through.
        other = Vehicle("2.0")
        other.last_node_id = "p3"
        forged = {**Headers("2.0", "acme", "F-0043").next("state", 0.0), **other.state(Pose(7.925, 2.925), 0.0, 0.0)}
        await rogue.publish("uagv/v2/acme/F-0043/state", json.dumps(forged), qos=1)
        await rogue.publish("uagv/v2/acme/F-0042/state", b"marker: not json", qos=1)
        await wait_for(lambda: "not JSON" in db.value("_sys.vda5050.r01.error"), 10, "the marker through")
        assert not db.value("r02_online") and adapter(runtime, "vda5050").links["r02"].states == 0
    finally:
        for task in (driving, roguing):
            task.cancel()
        await asyncio.gather(driving, roguing, return_exceptions=True)
        await rogue.close()
        await runtime.stop()
