"""`softplc read | write | forces` and the shared login options, against a real runtime over loopback.

The runtime (with its OPC UA server on a free port) runs in the test's event loop; each command
runs in its own process, exactly as a user types it.
"""

from __future__ import annotations

import asyncio
import datetime
import json
import os
import re
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from softplc.adapters.opcua import OpcUaServer, Pki
from softplc.app.runtime import Runtime
from softplc.core.datatypes import TypeMismatch
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, WriteRejected
from softplc.protocols.opcua_client import ensure_client_certificate
from tests.conftest import REPO
from tests.opcua_support import PASSWORDS, running_plant, wait_until

ENGINEER = Origin("test", "tester", role=Role.ENGINEER)


async def softplc(*arguments: str, home: Path, password: str | None = None, stdin: str | None = None,
                  timeout: float = 60) -> tuple[int, str, str]:
    """`softplc ARGUMENTS` in its own process; returns (exit status, stdout, stderr)."""
    env = dict(os.environ, PYTHONPATH=str(REPO), HOME=str(home))  # HOME: client certificates stay in the test's folder
    env.pop("SOFTPLC_PASSWORD", None)
    if password is not None:
        env["SOFTPLC_PASSWORD"] = password
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "softplc.app.cli", *arguments, env=env,
        stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(process.communicate(stdin.encode() if stdin is not None else b""), timeout)
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


@pytest.fixture
async def plant(tmp_path: Path) -> AsyncIterator[tuple[Runtime, OpcUaServer]]:
    async with running_plant(tmp_path) as started:
        yield started


async def force(runtime: Runtime, tag: str, value: Any) -> None:
    await runtime.commands.call("tags.force", {"tag": tag, "value": value}, ENGINEER)
    await wait_until(lambda: runtime.db[tag].forced)


def table(text: str) -> dict[str, list[str]]:
    """A printed table's rows by their first cell (columns split on two or more spaces; a note in brackets ends it)."""
    rows = {}
    for line in text.splitlines()[2:]:
        if line.startswith("("):
            break
        cells = re.split(r"\s{2,}", line.strip())
        rows[cells[0]] = cells[1:]
    return rows


def utc(seconds: float) -> str:
    """A tag timestamp as the live commands print it."""
    return datetime.datetime.fromtimestamp(seconds, datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


async def test_read_shows_value_quality_forced_mark_and_time(plant, tmp_path: Path) -> None:
    runtime, server = plant
    await force(runtime, "i32", 42)
    code, out, err = await softplc("read", "i32", "s1", "r0?_xgoal", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 0, err
    rows = table(out)
    assert list(rows) == ["i32", "s1", "r01_xgoal", "r02_xgoal"]  # names in order, globs expanded in address-space order
    assert rows["i32"][:3] == ["42", "good", "F"]
    assert rows["s1"] == ["hello", "good", utc(runtime.db["s1"].timestamp)]  # not forced: no F
    assert rows["i32"][3] == utc(runtime.db["i32"].timestamp)  # when the force took effect
    code, out, err = await softplc("read", "i32", "f32", "--format", "json", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 0, err
    readings = {r["tag"]: r for r in json.loads(out)}
    assert readings["i32"]["forced"] is True and readings["i32"]["status"] == "GoodLocalOverride"
    assert readings["f32"] == {**readings["f32"], "value": 0.0, "forced": False, "quality": "good"}


async def test_read_of_an_unknown_tag_names_it_with_a_hint(plant, tmp_path: Path) -> None:
    _, server = plant
    code, out, err = await softplc("read", "i16", "f33", "r9*", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 1 and out == ""
    assert err.strip() == "softplc read: no such tag 'f33' (did you mean 'f32'?); no such tag 'r9*' (no tag matches this pattern)"


async def test_reading_exact_names_browses_nothing_a_pattern_does(plant, tmp_path: Path) -> None:
    # A browse of the whole address space holds the server's loop (0.15-0.4 s a level with
    # 1,000 alarm conditions): exact names are read at once, only a pattern needs the names.
    _, server = plant
    view = server.server.iserver.view_service
    browse = view.browse
    browsed: list[int] = []

    def counting(parameters: Any) -> Any:
        browsed.append(len(parameters.NodesToBrowse))
        return browse(parameters)

    view.browse = counting
    code, out, err = await softplc("read", "i32", "s1", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 0, err
    assert list(table(out)) == ["i32", "s1"]
    assert browsed == []
    code, out, err = await softplc("read", "i3?", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 0, err
    assert list(table(out)) == ["i32"] and browsed
    browsed.clear()
    code, out, err = await softplc("read", "i32", "f33", "--endpoint", server.endpoint, home=tmp_path)
    assert (code, out) == (1, "")  # an unknown exact name is still named, with the hint the names give
    assert err.strip() == "softplc read: no such tag 'f33' (did you mean 'f32'?)"


async def test_write_is_applied_and_typed_text_is_parsed_by_the_tag_type(plant, tmp_path: Path) -> None:
    runtime, server = plant
    code, out, err = await softplc("write", "request=12", "b1=on", "f32=0.1", "s1=a=b", "--user", "operator",
                                   "--endpoint", server.endpoint, password=PASSWORDS["operator"], home=tmp_path)
    assert code == 0, err
    assert "request: 0 → 12 (accepted: applied at the next scan cycle)" in out.splitlines()
    await wait_until(lambda: runtime.db.value("reply") == 12)  # the program saw the client's value
    assert runtime.db.value("b1") is True and runtime.db.value("s1") == "a=b"
    assert runtime.db.value("f32") == runtime.db["f32"].definition.type.coerce(0.1)  # float32 0.1


# Each case: (TAG=VALUE, role, the value as the runtime's validation sees it). The CLI must print
# the runtime's own message for that write, word for word.
REFUSALS = [
    ("f32=11", "operator", 11.0, 1),            # out of range (max 10)
    ("i16=-101", "operator", -101, 1),          # out of range (min -100)
    ("ro_i32=8", "operator", 8, 1),             # read-only for clients
    ("_sys.error=oops", "engineer", "oops", 1),  # a diagnostic tag: no role writes it
    ("i16=5", "viewer", 5, 4),                  # a viewer may not write at all: not allowed
]


@pytest.mark.parametrize(("item", "role", "value", "status"), REFUSALS)
async def test_a_refused_write_gives_the_runtime_message_and_status(plant, tmp_path: Path, item, role, value, status) -> None:
    runtime, server = plant
    tag = item.split("=")[0]
    before = runtime.db.value(tag)
    with pytest.raises(WriteRejected) as expected:
        runtime.db.validate(tag, value, role=Role(role))
    code, out, err = await softplc("write", item, "--user", role, "--endpoint", server.endpoint, password=PASSWORDS[role], home=tmp_path)
    assert code == status
    assert err.splitlines()[0] == str(expected.value)
    assert runtime.db.value(tag) == before


async def test_a_value_that_does_not_parse_writes_nothing(plant, tmp_path: Path) -> None:
    runtime, server = plant
    code, out, err = await softplc("write", "request=5", "i16=abc", "u16=70000", "--user", "operator",
                                   "--endpoint", server.endpoint, password=PASSWORDS["operator"], home=tmp_path)
    assert code == 1 and out == ""
    for tag, text in (("i16", "abc"), ("u16", "70000")):
        with pytest.raises(TypeMismatch) as expected:
            runtime.db[tag].definition.type.parse(text)
        assert f"{WriteRejected(tag, Rule.TYPE_MISMATCH, str(expected.value))}" in err.splitlines()
    assert err.splitlines()[-1] == "softplc write: nothing written"
    await asyncio.sleep(0.05)  # several 10 ms cycles: a journaled write would have landed
    assert runtime.db.value("request") == 0


async def test_a_write_to_a_forced_tag_is_refused_with_the_runtime_message(plant, tmp_path: Path) -> None:
    runtime, server = plant
    await force(runtime, "request", 3)
    with pytest.raises(WriteRejected) as expected:
        runtime.db.validate("request", 9, role=Role.OPERATOR)
    code, out, err = await softplc("write", "request=9", "i32=4", "--user", "operator", "--endpoint", server.endpoint,
                                   password=PASSWORDS["operator"], home=tmp_path)
    assert code == 1
    assert err.splitlines() == [str(expected.value)]
    assert out.splitlines() == ["i32: 0 → 4 (accepted: applied at the next scan cycle)"]  # the other item is not affected
    await wait_until(lambda: runtime.db.value("i32") == 4)
    assert runtime.db.value("request") == 3


async def test_bad_assignment_syntax_is_a_usage_error(tmp_path: Path) -> None:
    code, out, err = await softplc("write", "i16", "--endpoint", "opc.tcp://127.0.0.1:1/", home=tmp_path)
    assert code == 2 and err.strip() == "softplc write: 'i16' is not TAG=VALUE (e.g. t01_iFr=45 or r01_status=true)"


async def test_forces_lists_the_forced_tags_with_who_forced_them(plant, tmp_path: Path) -> None:
    runtime, server = plant
    code, out, err = await softplc("forces", "--endpoint", server.endpoint, home=tmp_path)
    assert (code, out.strip()) == (0, "no forced tags"), err
    await force(runtime, "b1", True)
    await force(runtime, "f32", "2.5")
    since = {f.tag: f.since for f in runtime.db.forces.active()}
    code, out, err = await softplc("forces", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 0, err
    rows = table(out)
    assert rows == {"b1": ["true", utc(since["b1"]), "test:tester"], "f32": ["2.5", utc(since["f32"]), "test:tester"]}
    code, out, err = await softplc("forces", "--format", "json", "--endpoint", server.endpoint, home=tmp_path)
    assert [(f["tag"], f["value"], f["by"]) for f in json.loads(out)] == [("b1", True, "test:tester"), ("f32", 2.5, "test:tester")]


async def test_forces_of_a_server_without_the_commands_door_come_from_good_local_override(plant, tmp_path: Path) -> None:
    runtime, server = plant
    await force(runtime, "i32", 42)
    from asyncua import ua

    await server.server.delete_nodes([server.server.get_node(ua.NodeId("Commands", server.namespace_index))], recursive=True)
    code, out, err = await softplc("forces", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 0, err
    assert table(out) == {"i32": ["42", utc(runtime.db["i32"].timestamp), "?"]}
    assert out.splitlines()[-1] == "(this server has no OPC UA door to the runtime's commands: who forced a tag is not known here)"
    code, _, err = await softplc("force", "i32=1", "--user", "engineer", "--endpoint", server.endpoint, password=PASSWORDS["engineer"], home=tmp_path)
    assert code == 1 and "this server has no OPC UA door to the runtime's commands" in err


async def test_an_engineer_forces_and_unforces_from_the_command_line(plant, tmp_path: Path) -> None:
    runtime, server = plant
    engineer = ("--user", "engineer", "--endpoint", server.endpoint)
    code, out, err = await softplc("force", "request=7", "f32=2.5", *engineer, password=PASSWORDS["engineer"], home=tmp_path)
    assert code == 0, err
    assert out.splitlines() == ["request forced to 7 from the next cycle", "f32 forced to 2.5 from the next cycle"]
    await wait_until(lambda: runtime.db["request"].forced and runtime.db.value("reply") == 7)  # the program reads the forced value
    assert all(str(f.origin).startswith("opcua:engineer@127.0.0.1:") for f in runtime.db.forces.active())  # who, for the audit
    # An operator may not force: refused by role, exit status 4.
    code, out, err = await softplc("force", "i16=1", "--user", "operator", "--endpoint", server.endpoint, password=PASSWORDS["operator"], home=tmp_path)
    assert code == 4 and out == ""
    assert "tags.force: this session's role may not do that (BadUserAccessDenied)" in err and "engineer role" in err
    assert not runtime.db["i16"].forced
    # The runtime's refusals, in its words: a value of the wrong type, an unknown tag, a tag not forced.
    code, _, err = await softplc("force", "i16=abc", *engineer, password=PASSWORDS["engineer"], home=tmp_path)
    assert code == 1 and err.strip() == "softplc force: i16: type mismatch: expected int16, got 'abc'"
    code, out, err = await softplc("unforce", "request", "i16", "f32", "--restore", *engineer, password=PASSWORDS["engineer"], home=tmp_path)
    assert code == 1
    assert out.splitlines() == ["request unforced and restored from the next cycle", "f32 unforced and restored from the next cycle"]
    assert err.strip() == "softplc unforce: i16 is not forced"
    await wait_until(lambda: not runtime.db.forces and runtime.db.value("f32") == 0.0)


# -- logging in ------------------------------------------------------------------------------


async def test_wrong_password_is_refused_with_exit_status_4(plant, tmp_path: Path) -> None:
    _, server = plant
    code, out, err = await softplc("read", "i16", "--user", "operator", "--endpoint", server.endpoint, password="not-the-password", home=tmp_path)
    assert code == 4 and out == ""
    assert err.strip() == (f"softplc read: {server.endpoint}: login refused: wrong user name or password, "
                           "or too many failed logins from here (wait a minute) (BadUserAccessDenied)")


async def test_the_password_comes_from_stdin_or_is_asked_for(plant, tmp_path: Path) -> None:
    runtime, server = plant
    code, out, err = await softplc("write", "i16=7", "--user", "operator", "--password-stdin", "--endpoint", server.endpoint,
                                   stdin=PASSWORDS["operator"] + "\n", home=tmp_path)
    assert code == 0, err
    await wait_until(lambda: runtime.db.value("i16") == 7)
    # No terminal to ask on, and nothing given: a clear refusal before connecting.
    code, out, err = await softplc("write", "i16=8", "--user", "operator", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 4
    assert err.strip() == "softplc write: no password for --user operator: give --password-stdin or $SOFTPLC_PASSWORD (no terminal to ask on)"


async def test_nothing_listening_is_exit_status_3(tmp_path: Path) -> None:
    import socket

    with socket.socket() as probe:  # a port that was free a moment ago: nothing listens on it
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    endpoint = f"opc.tcp://127.0.0.1:{port}/softplc/"
    code, out, err = await softplc("read", "i16", "--endpoint", endpoint, home=tmp_path)
    assert code == 3
    assert err.strip() == f"softplc read: cannot connect to {endpoint}: connection refused (is `softplc run` serving OPC UA there?)"


async def test_anonymous_refused_says_to_log_in(tmp_path: Path) -> None:
    async with running_plant(tmp_path, anonymous="off") as (_, server):
        code, _, err = await softplc("read", "i16", "--endpoint", server.endpoint, home=tmp_path)
    assert code == 4 and "log in with --user NAME" in err


async def test_signed_and_encrypted_session_with_a_made_certificate(plant, tmp_path: Path) -> None:
    runtime, server = plant
    arguments = ("read", "i16", "--security", "SignAndEncrypt", "--user", "engineer", "--endpoint", server.endpoint)
    # First: the server does not know the certificate the command makes (~/.softplc/client/) and says what to run.
    code, _, err = await softplc(*arguments, password=PASSWORDS["engineer"], home=tmp_path)
    made = ensure_client_certificate(tmp_path / ".softplc" / "client", "softplc-client")
    assert code == 4
    assert "does not trust this client's certificate" in err and f"softplc opcua trust {made.fingerprint[:16]}" in err
    Pki(runtime.state_dir / "pki").trust(made.fingerprint[:16])
    code, out, err = await softplc(*arguments, password=PASSWORDS["engineer"], home=tmp_path)
    assert code == 0, err
    assert table(out)["i16"][:2] == ["0", "good"]


async def test_the_endpoint_and_namespace_come_from_the_plant_configuration(tmp_path: Path) -> None:
    async with running_plant(tmp_path, namespace="urn:example:line2") as (_, server):
        port = server.endpoint.split(":")[2].split("/")[0]
        plant = tmp_path / "line2.yaml"  # what a client needs of the plant's tagdb.yaml: its servers.opcua
        plant.write_text(f"servers:\n  opcua:\n    endpoint: opc.tcp://0.0.0.0:{port}/softplc/\n    namespace: urn:example:line2\n")
        code, out, err = await softplc("read", "i16", "--config", str(plant), home=tmp_path)
        assert code == 0, err  # the endpoint (a server listening everywhere: reached on loopback) and namespace of the file
        assert table(out)["i16"][:2] == ["0", "good"]
        # --endpoint overrides the configuration's; its namespace still counts
        elsewhere = tmp_path / "elsewhere.yaml"
        elsewhere.write_text("servers:\n  opcua:\n    endpoint: opc.tcp://127.0.0.1:9/softplc/\n    namespace: urn:example:line2\n")
        code, out, err = await softplc("read", "i16", "--config", str(elsewhere), "--endpoint", server.endpoint, home=tmp_path)
        assert code == 0, err
        code, _, err = await softplc("read", "i16", "--endpoint", server.endpoint, home=tmp_path)
        assert code == 3 and "has no namespace urn:softplc:tags" in err
        code, _, err = await softplc("read", "i16", "--endpoint", server.endpoint, "--namespace", "urn:example:line3", home=tmp_path)
        assert code == 3 and "has no namespace urn:example:line3: it is not a softplc runtime (is --namespace right?)" in err
    code, _, err = await softplc("read", "i16", "--config", str(tmp_path / "nowhere.yaml"), home=tmp_path)
    assert code == 2 and f"--config {tmp_path / 'nowhere.yaml'}: no such file" in err
