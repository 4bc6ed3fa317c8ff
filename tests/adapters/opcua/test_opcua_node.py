"""An independent client none of us wrote (node-opcua, npm) browses, reads, writes and subscribes.

Needs `node` and tests/node/node_modules (scripts/install-test-tools.sh runs `npm install` there).
"""

from __future__ import annotations

import asyncio
import json
import shutil
from datetime import datetime

import pytest

from softplc.adapters.opcua import Pki
from softplc.security.certificates import fingerprint
from tests.conftest import REPO
from tests.opcua_support import PASSWORDS, make_client_certificate, running_plant

NODE_DIR = REPO / "tests" / "node"


def _require_node_opcua() -> str:
    node = shutil.which("node")
    if node is None:
        pytest.fail("node is not installed: run scripts/install-test-tools.sh (needs Node.js and npm)")
    if not (NODE_DIR / "node_modules" / "node-opcua-client").is_dir():
        pytest.fail("node-opcua-client is not installed: run scripts/install-test-tools.sh (npm install in tests/node)")
    return node


async def _run(node: str, *arguments: str, script: str = "opcua_check.js") -> tuple[int, dict | None, str]:
    process = await asyncio.create_subprocess_exec(
        node, script, *arguments, cwd=NODE_DIR, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )
    stdout, stderr = await asyncio.wait_for(process.communicate(), 60)
    results = [line[len("RESULT "):] for line in stdout.decode().splitlines() if line.startswith("RESULT ")]
    return process.returncode or 0, (json.loads(results[0]) if results else None), (stderr + stdout).decode()[-3000:]


def _check(seen: dict, runtime, server) -> None:
    assert seen["namespaceIndex"] == server.namespace_index
    assert any(name.endswith("Plant") for name in seen["objects"]) and any(name.endswith("Diagnostics") for name in seen["objects"])
    assert seen["plant"][0] == "Robots" and "s1" in seen["plant"]
    assert seen["s1"] == "hello"
    assert seen["i16DataType"] == "ns=0;i=4"  # Int16
    assert (seen["roAccessLevel"], seen["rwAccessLevel"]) == (1, 3)
    assert seen["i16Range"] == {"low": -100, "high": 100}
    assert seen["writes"] == ["Good", "BadNotWritable", "BadOutOfRange", "BadTypeMismatch", "Good"]
    counts = seen["counts"]
    assert len(counts) >= 10 and counts == sorted(counts)
    assert runtime.db.value("i32") == 4321 and runtime.db.value("f32") == 2.5
    assert runtime.db.value("ro_i32") == 7 and runtime.db.value("i16") == 0


async def test_node_opcua_client_browses_reads_writes_and_subscribes(tmp_path) -> None:
    node = _require_node_opcua()
    async with running_plant(tmp_path, security=("None",)) as (runtime, server):
        code, seen, output = await _run(node, server.endpoint, "operator", PASSWORDS["operator"])
        assert code == 0 and seen is not None, output
        _check(seen, runtime, server)


async def test_node_opcua_over_sign_and_encrypt_after_its_certificate_is_trusted(tmp_path) -> None:
    node = _require_node_opcua()
    certificate = make_client_certificate(tmp_path, "node-opcua-client")
    trusted_flag = tmp_path / "trusted.flag"
    async with running_plant(tmp_path, security=("Basic256Sha256_SignAndEncrypt",), anonymous="off") as (runtime, server):
        process = await asyncio.create_subprocess_exec(
            node, "opcua_check.js", server.endpoint, "operator", PASSWORDS["operator"],
            "SignAndEncrypt", str(tmp_path / "node-opcua-client.cert.pem"), str(certificate.private_key), certificate.application_uri,
            str(trusted_flag),
            cwd=NODE_DIR, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )
        assert process.stdout is not None
        lines: list[str] = []
        while True:  # node-opcua logs on stdout too: read until its verdict on the first attempt
            line = (await asyncio.wait_for(process.stdout.readline(), 60)).decode()
            assert line, "node script ended early: " + "".join(lines)[-2000:]
            lines.append(line)
            if line.startswith("REFUSED "):
                break
        assert line.split()[1] == "BadCertificateUntrusted"
        pki = Pki(tmp_path / "state" / "pki")
        assert [info.fingerprint for info in pki.list(pki.rejected_dir)] == [fingerprint(certificate.der)]
        pki.trust(fingerprint(certificate.der)[:16])
        trusted_flag.touch()
        rest, stderr = await asyncio.wait_for(process.communicate(), 60)
        results = [entry[len("RESULT "):] for entry in rest.decode().splitlines() if entry.startswith("RESULT ")]
        assert process.returncode == 0 and results, (stderr + rest).decode()[-3000:]
        _check(json.loads(results[0]), runtime, server)


async def test_node_opcua_sees_current_time_deadbands_and_spec_statuses(tmp_path) -> None:
    """Issue 14, OPC UA items 1-6 and 9 as an independent client sees them (tests/node/opcua_services_check.js)."""
    node = _require_node_opcua()
    async with running_plant(tmp_path, security=("None",)) as (runtime, server):
        code, seen, output = await _run(node, server.endpoint, "operator", PASSWORDS["operator"], script="opcua_services_check.js")
    assert code == 0 and seen is not None, output
    # 1. CurrentTime is a DateTime that tells the time and advances; ServerStatus's too, never before StartTime.
    first, second = seen["times"]
    for reading in (first, second):
        assert reading["dataType"] == 13  # DateTime, not Null
        assert abs(_seconds(reading["currentTime"]) - _seconds(reading["clientTime"])) < 2
        assert _seconds(reading["statusCurrentTime"]) >= _seconds(reading["statusStartTime"])
    assert _seconds(second["currentTime"]) - _seconds(first["currentTime"]) >= 1.0
    assert _seconds(second["statusCurrentTime"]) - _seconds(first["statusCurrentTime"]) >= 1.0
    changes = [_seconds(text) for text in seen["currentTimeChanges"]]
    # the value when the item was created, then one a second
    assert len(changes) >= 3 and changes == sorted(changes) and changes[-1] - changes[-2] >= 0.99, seen["currentTimeChanges"]
    # 2, 3. Deadbands compare with the last reported value: a drift of 1 per scan is reported every
    # 11 scans under an absolute deadband of 10 and a percent deadband of 1 % of EURange 0..1000.
    for values in (seen["absolute"], seen["percent"]):
        assert len(values) >= 8, values
        assert all(abs(later - earlier) > 10 for earlier, later in zip(values, values[1:])), values
    # 3, 4, 6. Filters that do not fit are refused per item; queue sizes revised (0 -> 1, capped at 100).
    assert seen["created"] == [
        ["BadFilterNotAllowed", 0], ["BadFilterNotAllowed", 0], ["BadDeadbandFilterInvalid", 0], ["BadDeadbandFilterInvalid", 0],
        ["Good", 1], ["Good", 100],
    ]
    # 5. HistoryRead, 9. Call.
    assert seen["history"] == ["BadNodeIdUnknown", "BadHistoryOperationUnsupported"]
    assert seen["calls"] == ["BadMethodInvalid", "BadNodeIdUnknown"]


def _seconds(iso: str) -> float:
    return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()
