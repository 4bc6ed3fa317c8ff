"""The case IV handshake program on the simulated clock, with a simulated client writing via db.submit."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field

import pytest
from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.config import PlantConfig, load_config
from softplc.core.clock import SimClock
from softplc.engine.scan import ProgramState

HANDSHAKE_YAML = REPO / "programs" / "handshake.yaml"


def handshake_config(scenario: str = "fast", scan: str = "10ms") -> PlantConfig:
    """programs/handshake.yaml with the scenario and scan applied (as `softplc latency` does)."""
    import yaml

    from softplc.config import parse_config

    data = yaml.safe_load(HANDSHAKE_YAML.read_text())
    data["tasks"]["handshake"]["interval"] = scan
    data["tasks"]["handshake"]["programs"][0]["params"] = {"scenario": scenario, "scan_interval": scan}
    return parse_config(yaml.safe_dump(data), HANDSHAKE_YAML)


@dataclass
class SimulatedClient:
    """Answers each Ready after `response(n)` seconds with the next TaskID, like the thesis's client."""

    runtime: Runtime
    response: Callable[[int], float]
    clear_ready: str = "together"  # together | first | never
    answered: int = 0
    ready_times: list[float] = field(default_factory=list)
    answer_times: list[float] = field(default_factory=list)
    next_task: int = 1

    async def run(self, handshakes: int) -> None:
        db, clock = self.runtime.db, self.runtime.clock
        ready = asyncio.Event()

        def on_change(tags: object) -> None:
            for tag in tags:  # type: ignore[attr-defined]
                if tag.name == "Ready" and tag.value:
                    self.ready_times.append(clock.now())
                    ready.set()

        unsubscribe = db.on_change(on_change)
        try:
            while self.answered < handshakes:
                await asyncio.wait_for(ready.wait(), 5.0)
                ready.clear()
                await clock.sleep(self.response(self.answered))
                self.answer_times.append(clock.now())
                if self.clear_ready == "first":
                    db.submit([("Ready", False)], "client")
                    await clock.sleep(0.01)  # the TaskID lands one scan later
                    db.submit([("TaskID", self.next_task)], "client")
                elif self.clear_ready == "never":
                    db.submit([("TaskID", self.next_task)], "client")
                else:
                    assert db.submit([("TaskID", self.next_task), ("Ready", False)], "client") == [None, None]
                self.next_task = self.next_task % 3 + 1
                self.answered += 1
        finally:
            unsubscribe()


async def run_handshakes(runtime: Runtime, client: SimulatedClient, handshakes: int) -> list[dict[str, float]]:
    """Start the runtime, let the client answer `handshakes` times, collect the PLC's results."""
    results: list[dict[str, float]] = []

    def on_change(tags: object) -> None:
        if any(tag.name == "Handshakes" for tag in tags):  # type: ignore[attr-defined]
            results.append(runtime.db.snapshot(["Handshakes", "Delay", "DelayScans", "TaskID", "ReadyStamp"]))

    runtime.db.on_change(on_change)
    await runtime.start()
    try:
        await client.run(handshakes)
        deadline = runtime.clock.now() + 1.0
        while len(results) < handshakes - 1 and runtime.clock.now() < deadline:
            await runtime.clock.sleep(0.01)
    finally:
        await runtime.stop()
    return results


async def test_fast_response_is_one_scan_and_tasks_cycle(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.003)
    results = await run_handshakes(runtime, client, 7)
    # The first answer starts the sequence (TaskID 0 -> 1): not a timed switch.
    assert [r["Handshakes"] for r in results] == [1, 2, 3, 4, 5, 6]
    assert [r["DelayScans"] for r in results] == [1] * 6
    assert all(r["Delay"] == pytest.approx(10.0) for r in results)
    assert [r["TaskID"] for r in results] == [2, 3, 1, 2, 3, 1]
    assert runtime.program("handshake").state is ProgramState.RUNNING


async def test_task_durations_follow_the_scenario(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.003)
    await run_handshakes(runtime, client, 7)
    # Ready k+1 follows the PLC seeing answer k (at the next scan) by the task's duration.
    durations = {1: 0.1, 2: 0.2, 3: 0.5}
    for index in range(6):
        task = index % 3 + 1
        seen = (client.answer_times[index] // 0.01 + 1) * 0.01
        elapsed = client.ready_times[index + 1] - seen
        assert durations[task] - 1e-9 <= elapsed <= durations[task] + 0.01 + 1e-9, (index, elapsed)


async def test_slow_answers_are_quantised_to_scans(tmp_path):
    responses = [0.001, 0.015, 0.025, 0.0449, 0.005]
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: responses[n % len(responses)])
    results = await run_handshakes(runtime, client, 5)
    # Answer after r seconds lands in the journal and is seen at the first scan after it.
    assert [r["DelayScans"] for r in results] == [2, 3, 5, 1]
    assert [r["Delay"] for r in results] == pytest.approx([20.0, 30.0, 50.0, 10.0])


async def test_one_ms_scan(tmp_path):
    runtime = Runtime(handshake_config("fast", "1ms"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.0025)
    results = await run_handshakes(runtime, client, 4)
    assert [r["DelayScans"] for r in results] == [3, 3, 3]
    assert [r["Delay"] for r in results] == pytest.approx([3.0, 3.0, 3.0])


async def test_ready_stamp_is_when_ready_was_set(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.002)
    stamps: list[float] = []
    runtime.db.on_change(lambda tags: stamps.extend(t.value for t in tags if t.name == "ReadyStamp"))
    await run_handshakes(runtime, client, 4)
    # The simulated clock's monotonic() is its now(): the stamp is the time of the setting scan.
    # (The first Ready is set at t = 0, the stamp's initial value, so it is no change.)
    assert client.ready_times[0] == 0.0
    assert len(stamps) == 3
    assert stamps == pytest.approx(client.ready_times[1:4])


async def test_ready_cleared_before_taskid_still_times_to_the_taskid(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.002, clear_ready="first")
    results = await run_handshakes(runtime, client, 4)
    assert [r["DelayScans"] for r in results] == [2, 2, 2]


async def test_plc_clears_ready_when_the_client_does_not(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.002, clear_ready="never")
    results = await run_handshakes(runtime, client, 4)
    assert [r["Handshakes"] for r in results] == [1, 2, 3]
    assert [r["DelayScans"] for r in results] == [1, 1, 1]


async def test_running_task_and_no_switch_without_a_new_taskid(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    await runtime.start()
    try:
        clock, db = runtime.clock, runtime.db
        await clock.sleep(0.05)
        assert db.value("Ready") is True and db.value("RunningTask") == 0
        db.submit([("TaskID", 1), ("Ready", False)], "client")
        await clock.sleep(0.05)
        assert db.value("RunningTask") == 1 and db.value("Ready") is False
        await clock.sleep(0.1)
        assert db.value("Ready") is True and db.value("RunningTask") == 0
        # The same TaskID again is no answer: the PLC keeps waiting, nothing is counted.
        db.submit([("TaskID", 1)], "client")
        await clock.sleep(0.5)
        assert db.value("Ready") is True and db.value("Handshakes") == 0
        # Out-of-range TaskIDs are rejected by the tag's limits, never reach the program.
        rejected = db.submit([("TaskID", 4)], "client")[0]
        assert rejected is not None and rejected.rule.value == "out of range"
    finally:
        await runtime.stop()


def test_unknown_scenario_faults_the_program(tmp_path):
    from softplc.config.yamlsource import ConfigError

    # A bad duration is a configuration error with its location...
    with pytest.raises(ConfigError):
        handshake_config("fast", "fast")

    # ...a bad scenario faults the program at setup, with the reason.
    async def check() -> None:
        runtime = Runtime(handshake_config("medium"), SimClock(), state_dir=tmp_path)
        await runtime.start()
        try:
            await runtime.clock.sleep(0.05)
            instance = runtime.program("handshake")
            assert instance.state is ProgramState.FAULTED
            assert "unknown scenario 'medium'" in instance.error
        finally:
            await runtime.stop()

    asyncio.run(check())


def test_shipped_config_loads():
    config = load_config(HANDSHAKE_YAML)
    assert {d.name for d in config.tags} >= {"Ready", "TaskID", "Delay", "DelayScans", "Handshakes", "ReadyStamp"}


async def scans(runtime: Runtime, count: int) -> None:
    """Let `count` scans of the 10 ms task run (the simulated clock jumps)."""
    await runtime.clock.sleep(0.01 * count + 0.001)


async def test_taskid_while_a_task_runs_is_followed_and_counted_as_unexpected(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    await runtime.start()
    try:
        db = runtime.db
        await scans(runtime, 2)
        db.submit([("TaskID", 1), ("Ready", False)], "client")  # starts the sequence
        await scans(runtime, 2)
        assert db.value("RunningTask") == 1 and db.value("Ready") is False
        # Task 1 (100 ms) is running: nobody asked for a TaskID.
        db.submit([("TaskID", 3)], "someone else")
        await scans(runtime, 2)
        assert db.value("RunningTask") == 3 and db.value("Unexpected") == 1
        assert db.value("Handshakes") == 0  # no handshake, nothing timed
        # Task 3 runs its full 500 ms from the switch; the next Ready is answered as usual.
        await scans(runtime, 48)
        assert db.value("Ready") is False
        await scans(runtime, 3)
        assert db.value("Ready") is True and db.value("RunningTask") == 0
        db.submit([("TaskID", 1), ("Ready", False)], "client")
        await scans(runtime, 2)
        assert db.value("Handshakes") == 1 and db.value("Unexpected") == 1 and db.value("BadAnswers") == 0
    finally:
        await runtime.stop()


@pytest.mark.parametrize("answer", [1, 0], ids=["same TaskID", "TaskID 0"])
async def test_ready_cleared_without_a_valid_taskid_is_asked_again(tmp_path, answer):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    await runtime.start()
    try:
        db = runtime.db
        await scans(runtime, 2)
        db.submit([("TaskID", 1), ("Ready", False)], "client")
        await scans(runtime, 12)  # task 1 (100 ms) done: Ready again
        assert db.value("Ready") is True
        stamp = db.value("ReadyStamp")
        db.submit([("TaskID", answer), ("Ready", False)], "client")
        await scans(runtime, 1)
        assert db.value("Ready") is False  # one scan's grace for a TaskID sent separately
        await scans(runtime, 1)
        assert db.value("Ready") is True and db.value("BadAnswers") == 1
        assert db.value("ReadyStamp") == stamp  # the same request, still timed from its start
        # It keeps asking until a valid new TaskID arrives.
        db.submit([("Ready", False)], "client")
        await scans(runtime, 3)
        assert db.value("Ready") is True and db.value("BadAnswers") == 2
        db.submit([("TaskID", 2), ("Ready", False)], "client")
        await scans(runtime, 2)
        assert db.value("Handshakes") == 1 and db.value("RunningTask") == 2 and db.value("Ready") is False
        assert db.value("DelayScans") >= 7 and db.value("Unexpected") == 0
    finally:
        await runtime.stop()


async def test_a_client_clearing_ready_one_scan_before_the_taskid_is_no_bad_answer(tmp_path):
    runtime = Runtime(handshake_config("fast"), SimClock(), state_dir=tmp_path)
    client = SimulatedClient(runtime, response=lambda n: 0.002, clear_ready="first")
    await run_handshakes(runtime, client, 4)
    assert runtime.db.value("BadAnswers") == 0 and runtime.db.value("Unexpected") == 0
