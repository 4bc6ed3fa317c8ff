"""A redundant pair's files for tests: both members' certificates and one plant file naming them and the etcd."""

from __future__ import annotations

import socket
import textwrap
from pathlib import Path

from softplc.security.pair_certificates import make_pair

PLANT = """
version: 1
plant: {{name: pairtest}}
tags:
  part: {{type: bool, initial: true}}
  scans: {{type: uint32}}
  edges: {{type: uint32}}
  done: {{type: bool}}
  draw: {{type: float64}}
  setpoint: {{type: float64, retain: true}}
  spare: {{type: uint32}}
tasks:
  fast:
    interval: {interval}
    programs:
      - name: stateful
        program: tests.engine.replication_programs:Stateful
        bind: {{part: part, scans: scans, edges: edges, done: done, draw: draw}}
{servers}
{extra}
redundancy:
  preferred: a
  members:
    a: {{sync: "127.0.0.1:{sync_a}", listen: "127.0.0.1:{listen_a}", certificate: pair/a.crt, key: pair/a.key, opcua: "{opcua_a}", hmi: "{hmi_a}"}}
    b: {{sync: "127.0.0.1:{sync_b}", listen: "127.0.0.1:{listen_b}", certificate: pair/b.crt, key: pair/b.key, opcua: "{opcua_b}", hmi: "{hmi_b}"}}
  coordinator: {{endpoints: ["{etcd}"], lease: {lease}}}
  sync_lag_alarm: 1s
"""

NO_SERVERS = """
servers:
  opcua: {enabled: false}
  modbus: {enabled: false}
  hmi: {enabled: false}
"""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def write_pair(folder: Path, etcd: str, *, servers: str = NO_SERVERS, interval: str = "10ms", lease: str = "3s", ports: dict[str, int] | None = None,
               proxies: dict[str, int] | None = None, extra: str = "") -> Path:
    """Make pair/a.*, pair/b.* and tagdb.yaml in `folder`; `proxies`: member → the port the peer reaches it at (a proxy).

    `extra`: more top-level sections (history, alarms, audit...), YAML at the left margin. `lease`: 3 s
    unless a test judges the takeover after a kill (a loaded test machine can starve etcd for most
    of a second, and a 1 s lease then fences an active that is merely slow).
    """
    make_pair(folder / "pair", "a", "pairtest")
    make_pair(folder / "pair", "b", "pairtest")
    ports = ports or {}
    listen = {member: ports.get(f"sync_{member}") or free_port() for member in "ab"}
    sync = {member: (proxies or {}).get(member, listen[member]) for member in "ab"}
    text = textwrap.dedent(PLANT).format(
        interval=interval, lease=lease, servers=textwrap.dedent(servers), extra=textwrap.dedent(extra), etcd=etcd, listen_a=listen["a"], listen_b=listen["b"],
        sync_a=sync["a"], sync_b=sync["b"], opcua_a=ports.get("opcua_a_url", ""), opcua_b=ports.get("opcua_b_url", ""),
        hmi_a=ports.get("hmi_a_url", ""), hmi_b=ports.get("hmi_b_url", ""))
    path = folder / "tagdb.yaml"
    path.write_text(text)
    return path
