"""The configuration of a VDA 5050 plant: robots.yaml's vehicles, the roadmap, `vda5050:` and the embedded broker, each
mistake located; and the embedded broker (amqtt) carrying a whole order to a vda-5050-lib vehicle and back."""

from __future__ import annotations

import socket
import textwrap
from pathlib import Path

import pytest
from vda5050_support import MAP, LibVehicles, adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.config.yamlsource import ConfigError
from softplc.robotics.roadmap import parse_roadmap
from softplc.robotics.robots import parse_robots


def messages(error: ConfigError) -> list[str]:
    return [f"{problem.location.line}:{problem.location.column}: {problem.message}" for problem in error.problems]


def test_robots_yaml_says_what_a_vehicle_lacks() -> None:
    text = textwrap.dedent("""\
        robots:
          - {id: r01, driver: vda5050, length_mm: 1, width_mm: 1, height_mm: 1, load_capacity: 1, max_linear_speed: 1,
             max_angular_speed: 1, start: {x: 0, y: 0}}
          - {id: r02, driver: sim, vda5050: {manufacturer: a, serial_number: b}, length_mm: 1, width_mm: 1, height_mm: 1,
             load_capacity: 1, max_linear_speed: 1, max_angular_speed: 1, start: {x: 0, y: 0}}
          - {id: r03, driver: vda5050, vda5050: {manufacturer: a, serial_number: "b/c"}, length_mm: 1, width_mm: 1, height_mm: 1,
             load_capacity: 1, max_linear_speed: 1, max_angular_speed: 1, start: {x: 0, y: 0}}
    """)
    with pytest.raises(ConfigError) as caught:
        parse_robots(text)
    found = messages(caught.value)
    assert any(line.startswith("6:74: ") and "'b/c'" in line for line in found), found  # '/' cannot stand in a topic level


def test_robots_yaml_vehicle_checks_beyond_the_schema() -> None:
    base = "length_mm: 1, width_mm: 1, height_mm: 1, load_capacity: 1, max_linear_speed: 1, max_angular_speed: 1, start: {x: 0, y: 0}"
    text = textwrap.dedent(f"""\
        robots:
          - {{id: r01, driver: vda5050, {base}}}
          - {{id: r02, driver: sim, vda5050: {{manufacturer: a, serial_number: b}}, {base}}}
          - {{id: r03, driver: vda5050, vda5050: {{manufacturer: a, serial_number: c}}, {base}}}
          - {{id: r04, driver: vda5050, vda5050: {{manufacturer: a, serial_number: c}}, {base}}}
    """)
    with pytest.raises(ConfigError) as caught:
        parse_robots(text)
    found = messages(caught.value)
    assert found == [
        "2:23: robot r01 is a VDA 5050 vehicle: it needs 'vda5050: {manufacturer: ..., serial_number: ...}'",
        "3:28: robot r02 has a vda5050: section but 'driver: sim' (say 'driver: vda5050')",
        "5:74: vehicle a/c is robot r03 already",
    ], found


def test_roadmap_mistakes_are_located_with_hints() -> None:
    text = textwrap.dedent("""\
        roadmap:
          stations:
            - {id: s1, x: 0, y: 0}
            - {id: s1, x: 1, y: 0}
          waypoints:
            - {id: w1, x: 2, y: 0}
          lanes:
            - {from: s1, to: w2}
            - {from: w1, to: w1}
            - {from: s1, to: w1}
            - {from: w1, to: s1}
    """)
    with pytest.raises(ConfigError) as caught:
        parse_roadmap(text)
    assert messages(caught.value) == [
        "4:12: duplicate node id 's1'",
        "8:22: no node 'w2'",
        "9:7: lane from 'w1' to itself",
        "11:7: lane w1 → s1 declared twice",
    ]
    roadmap = parse_roadmap(text.replace("    - {id: s1, x: 1, y: 0}\n", "").replace("to: w2", "to: w1").replace(
        "    - {from: w1, to: w1}\n", "").replace("    - {from: s1, to: w1}\n    - {from: w1, to: s1}\n", ""))
    assert roadmap.route("s1", "w1") == ["s1", "w1"] and roadmap.lane("w1", "s1") is not None


def test_the_vda5050_and_mqtt_sections_are_checked(make_config, tmp_path: Path) -> None:
    (tmp_path / "robots.yaml").write_text("robots:\n" + textwrap.indent(vehicle_yaml("r01", "tb1", 1, 1), "  "))
    with pytest.raises(ConfigError) as caught:
        make_config(f"""
            version: 1
            tags: {{a: {{type: bool}}}}
            fleet: {{enabled: false, robots: robots.yaml, map: {MAP}}}
            mqtt: {{url: "mqtt://0.0.0.0:1884", embedded: true, protocol: "5"}}
            vda5050: {{roadmap: nowhere.yaml, lost_after: 0s, version: "2.1"}}
        """)
    assert messages(caught.value) == [
        "5:46: the embedded broker serves this computer only (loopback), not 0.0.0.0: it has no users or ACLs; run mosquitto "
        "for a network (docs/vda5050.md)",
        '5:62: the embedded broker (amqtt) speaks MQTT 3.1.1 only: protocol: "3.1.1"',
        "6:46: lost_after must be greater than zero",
    ]
    with pytest.raises(ConfigError) as caught:
        make_config(f"""
            version: 1
            tags: {{a: {{type: bool}}}}
            fleet: {{enabled: false, robots: robots.yaml, map: {MAP}}}
            vda5050: {{roadmap: nowhere.yaml}}
        """)
    assert [problem.message for problem in caught.value.problems] == [f"roadmap file not found: {tmp_path / 'nowhere.yaml'}"]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


async def test_the_embedded_broker_carries_an_order_to_a_vda_5050_lib_vehicle(tmp_path: Path) -> None:
    LibVehicles.require()
    port = free_port()
    robot = vehicle_yaml("r01", "v1", 7.925, 5.925, manufacturer="acme", key="instantActions", speed=1.0)
    tagdb = write_plant(tmp_path, f"mqtt://127.0.0.1:{port}", [robot])
    tagdb.write_text(tagdb.read_text().replace("keepalive: 2s}", "keepalive: 2s, embedded: true}"))
    runtime = await start_plant(tagdb)
    db = runtime.db
    try:
        assert adapter(runtime, "mqtt-broker").describe().startswith("embedded MQTT broker (amqtt; a demo, NOT for production)")
        async with LibVehicles(port, [{"manufacturer": "acme", "serialNumber": "v1", "x": 7.925, "y": 5.925, "lastNodeId": "p1"}]):
            await wait_for(lambda: db.value("r01_online"), 15, "the vehicle reports through the embedded broker")
            db.submit([("r01_xgoal", 7.925), ("r01_ygoal", 2.2), ("r01_status", True)], "test")
            await wait_for(lambda: db.value("r01_navstate") == "arrived", 30, "arrived")
            assert adapter(runtime, "vda5050").schema_violations == 0
    finally:
        await runtime.stop()
