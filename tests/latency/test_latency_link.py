"""`softplc latency --client link`: the case IV handshake between two softplc runtimes joined by a link (PLC to PLC).

Our runtime serves the handshake plant; a second `softplc run` of programs/handshake_answer.yaml
answers through an OPC UA link (with an operator login) or a Modbus link. Every answer is a
sample with the PLC's delay and the high-resolution split (Ready → the answering program saw it
→ our server took the answer); the PLC counts no TaskID out of turn.
"""

from __future__ import annotations

import json
import os
import signal

from softplc.latency.measurement import Measurement, Target, measure
from tests.latency.test_latency_run import check_run, run_cli

SAMPLES = 6


async def test_both_protocols_answered_by_a_linked_runtime_json() -> None:
    code, stdout, stderr = await run_cli("latency", "--client", "link", "--protocol", "all", "--scenario", "fast",
                                         "--samples", str(SAMPLES), "--json", timeout=240)
    assert code == 0, stderr
    runs = {run["protocol"]: run for run in json.loads(stdout)["runs"]}
    for protocol, name in (("opcua", "OPC UA"), ("modbus", "Modbus")):
        run = runs[protocol]
        check_run(run, protocol, SAMPLES)
        assert run["label"] == f"{name} PLC-PLC 10ms" and run["client"] == "link"
        assert run["plc_task"]["unexpected_taskids"] == 0  # never an answer to a Ready already answered
        # The answering program saw Ready after the PLC set it, and answered after it saw it.
        assert run["notify"]["best"] > 0.0 and run["respond"]["best"] > 0.0
    assert "PLC-PLC" in stderr


async def test_the_answering_runtime_dying_ends_the_run_with_its_samples() -> None:
    killed: list[int] = []

    def kill_after_two(run: Measurement) -> None:
        if len(run.samples) >= 2 and not killed and run.client_pid:
            os.kill(run.client_pid, signal.SIGKILL)
            killed.append(run.client_pid)

    result = await measure(Target("modbus", "fast", scan=0.01, client_mode="link", samples=50), kill_after_two)
    assert killed and len(result.samples) >= 2
    assert result.ended == "client died" and not result.complete
    assert any("the answering runtime exited with code -9" in error for error in result.errors), result.errors


def test_link_mode_plans_both_protocols_and_refuses_an_endpoint() -> None:
    import pytest

    from softplc.app.cli import build_parser
    from softplc.latency.cli import targets

    plan = targets(build_parser().parse_args(["latency", "--client", "link"]))
    assert [(target.protocol, target.mode) for target in plan] == [("opcua", "link"), ("modbus", "link")]
    with pytest.raises(ValueError, match="--client link runs both runtimes here: leave out --endpoint"):
        targets(build_parser().parse_args(["latency", "--client", "link", "--endpoint", "127.0.0.1:502"]))
