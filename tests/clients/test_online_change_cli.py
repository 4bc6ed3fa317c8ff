"""`softplc apply` against a running runtime over OPC UA (a real server, the command in its own process).

It calls `programs.apply` through the OPC UA door to the runtime's commands (softplc/adapters/opcua/commands.py).
"""

from __future__ import annotations

import asyncio
import os
import re
import sys
import textwrap
import uuid
from pathlib import Path

from conftest import REPO  # noqa: E402
from opcua_support import PASSWORDS, running_plant  # noqa: E402

PROGRAM = '''
from softplc import InOut, Output, Program


class Stamp(Program):
    count = InOut("scans")
    version = Output("code version")

    def setup(self):
        self.scans = 0

    def scan(self):
        self.scans += 1
        self.count += 1
        self.version = 1
'''

PLANT = """
version: 1
tags:
  count: {type: uint32}
  version: {type: uint16}
tasks:
  fast:
    interval: 10ms
    programs:
      - {name: stamp, program: "MODULE:Stamp", bind: {count: count, version: version}}
"""


async def softplc(*args: str, password: str | None = None) -> tuple[int, str, str]:
    """`softplc ARGS` in a process of its own, the password on its stdin; (exit status, stdout, stderr)."""
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "softplc.app.cli", *args, stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    out, err = await asyncio.wait_for(process.communicate(f"{password or ''}\n".encode()), 60)
    return process.returncode or 0, out.decode(), err.decode()


async def test_softplc_apply_changes_a_running_program_and_refuses_a_broken_change(tmp_path: Path) -> None:
    module = f"cli_{uuid.uuid4().hex[:10]}"
    source = tmp_path / f"{module}.py"
    source.write_text(textwrap.dedent(PROGRAM))
    async with running_plant(tmp_path, PLANT.replace("MODULE", module)) as (runtime, server):
        login = ["--endpoint", server.endpoint, "--user", "engineer", "--password-stdin", str(tmp_path / "tagdb.yaml")]
        source.write_text(source.read_text().replace("self.version = 1", "self.version = 2"))
        status, out, err = await softplc("apply", "--check", *login, password=PASSWORDS["engineer"])
        assert (status, err) == (0, "") and f"program stamp: code of {module} changed" in out and "checked, not applied" in out
        assert runtime.program("stamp").version == 1
        status, out, err = await softplc("apply", *login, password=PASSWORDS["engineer"])
        assert status == 0, err
        assert out.splitlines() == ["online change 1 applied: stamp", f"  program stamp: code of {module} changed",
                                    "  program stamp: new version RUNNING, state carried over: scans"]
        assert runtime.program("stamp").version == 2
        # a broken module: the runtime's located problem, exit 2, nothing applied
        source.write_text(source.read_text().replace("self.version = 2", "self.version = = 3"))
        status, out, err = await softplc("apply", *login, password=PASSWORDS["engineer"])
        assert status == 2 and out == ""
        assert err.startswith("online change refused, nothing applied: 1 problem:\n")
        assert "tagdb.yaml:10:" in err and re.search(rf"{re.escape(str(source.resolve()))}:\d+:\d+: SyntaxError: invalid syntax", err), err
        assert runtime.program("stamp").version == 2
        # an operator may not: exit 4 (the configuration as --config, the shared login option)
        status, out, err = await softplc("apply", "--endpoint", server.endpoint, "--user", "operator", "--password-stdin",
                                         "--config", str(tmp_path / "tagdb.yaml"), password=PASSWORDS["operator"])
        assert status == 4 and "user operator may not apply online changes" in err
        # a change that needs a restart: exit 5, the reason in the runtime's words
        source.write_text(source.read_text().replace("self.version = = 3", "self.version = 3"))
        config = tmp_path / "tagdb.yaml"
        config.write_text(config.read_text().replace("interval: 10ms", "interval: 20ms"))
        status, out, err = await softplc("apply", *login, password=PASSWORDS["engineer"])
        assert status == 5 and out == ""
        assert err.startswith("online change refused, nothing applied: changes that need a restart of the runtime:\n"), err
        assert runtime.program("stamp").version == 2


async def test_softplc_apply_without_a_runtime_is_exit_status_3(tmp_path: Path) -> None:
    (tmp_path / "plant.yaml").write_text("servers:\n  opcua:\n    endpoint: opc.tcp://127.0.0.1:9/softplc/\n")
    status, out, err = await softplc("apply", "--config", str(tmp_path / "plant.yaml"), "--user", "engineer", "--password-stdin",
                                     password="x")
    assert (status, out) == (3, ""), err
    assert err.strip() == ("softplc apply: cannot connect to opc.tcp://127.0.0.1:9/softplc/: connection refused "
                           "(is `softplc run` serving OPC UA there?)")
    status, _, err = await softplc("apply", str(tmp_path / "plant.yaml"), "--config", str(tmp_path / "other.yaml"))
    assert status == 2 and "two configurations" in err
