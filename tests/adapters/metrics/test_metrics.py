"""/metrics (softplc/adapters/metrics/): the default plant with every adapter `softplc run` starts, scraped over HTTP.

The figures are read back with prometheus_client's own parser, and moved by real clients: an
asyncua session and subscription, pymodbus requests, HMI writes and a force through the HMI's
commands door, a live WebSocket. Who may scrape (loopback, a bearer token, an HMI login) is
checked on a small plant. The histograms' scrape-time binning is unit-tested on a TimingSeries.
"""

from __future__ import annotations

import argparse
import stat
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
import pytest_asyncio
from asyncua import Client
from conftest import REPO  # noqa: E402
from hmi_support import PASSWORDS, add_users, start_plant, wait_until
from prometheus_client.parser import text_string_to_metric_families
from pymodbus.client import AsyncModbusTcpClient

from softplc.adapters.hmi.metrics_settings import MetricsSettings
from softplc.adapters.metrics.adapter import MetricsAdapter
from softplc.adapters.metrics.histograms import SeriesHistogram
from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import RealClock
from softplc.core.stats import TimingSeries

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def runtime(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Runtime]:
    """The default plant (tasks, fleet, historian, alarms, audit, OPC UA, Modbus, HMI) on free ports."""
    state = tmp_path_factory.mktemp("metrics") / "state"
    add_users(state)
    config = load_config(REPO / "tagdb.yaml")
    runtime = Runtime(config, RealClock(), state_dir=state)
    flags = argparse.Namespace(opcua_endpoint="opc.tcp://127.0.0.1:0/softplc/", modbus_port=0, hmi_port=0)
    for adapter in build_adapters(config, flags):
        runtime.add_adapter(adapter)
    await runtime.start()
    yield runtime
    await runtime.stop()


def adapter(runtime: Runtime, name: str) -> Any:
    return next(a for a in runtime.adapters if a.name == name)


def client() -> aiohttp.ClientSession:
    return aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True))


async def scrape(url: str, session: aiohttp.ClientSession | None = None, **headers: str) -> dict[str, float]:
    """Every sample of /metrics as {'name{label="v",...}': value} (labels sorted), via prometheus_client's parser."""
    own = session is None
    session = session or aiohttp.ClientSession()
    try:
        async with session.get(url + "metrics", headers=headers) as response:
            assert response.status == 200, await response.text()
            assert response.content_type == "text/plain"
            text = await response.text()
    finally:
        if own:
            await session.close()
    samples = {}
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            labels = ",".join(f'{key}="{value}"' for key, value in sorted(sample.labels.items()))
            samples[f"{sample.name}{{{labels}}}" if labels else sample.name] = sample.value
    return samples


async def test_the_default_plant_reports_its_tasks_programs_and_every_adapters_figures(runtime: Runtime) -> None:
    url = adapter(runtime, "hmi").url
    await wait_until(lambda: all(task.stats.cycles >= 2 for task in runtime.tasks), message="two cycles of every task")
    figures = await scrape(url)
    assert figures['softplc_info{plant="material-handling",simulated="false",version="0.1.0"}'] == 1
    assert figures['softplc_runtime_state{state="RUNNING"}'] == 1 and figures['softplc_runtime_state{state="ERROR"}'] == 0
    assert figures["softplc_tags"] == len(runtime.db) and figures["softplc_forced_tags"] == 0
    for task in runtime.tasks:
        label = f'task="{task.name}"'
        assert figures[f"softplc_task_interval_seconds{{{label}}}"] == task.interval
        for name in ("scan", "cycle", "start_latency"):
            count = figures[f"softplc_task_{name}_seconds_count{{{label}}}"]
            assert count == figures[f'softplc_task_{name}_seconds_bucket{{le="+Inf",{label}}}'] and count >= 1
        assert f"softplc_task_overruns_total{{{label}}}" in figures and f"softplc_task_watchdog_trips_total{{{label}}}" in figures
        for instance in task.programs:
            states = {state: figures[f'softplc_program_state{{program="{instance.name}",state="{state}",{label}}}']
                      for state in ("RUNNING", "STOPPED", "FAULTED")}
            assert states == {"RUNNING": 1, "STOPPED": 0, "FAULTED": 0}
            assert figures[f'softplc_program_faults_total{{program="{instance.name}",{label}}}'] == 0
    robots = {key: value for key, value in figures.items() if key.startswith("softplc_robots{")}
    assert sum(robots.values()) == len(adapter(runtime, "fleet").robots) == 3
    history = adapter(runtime, "history")
    assert figures["softplc_history_tags"] == len(history.filters) > 0
    assert "softplc_history_rows_written_total" in figures and "softplc_history_queue_rows" in figures
    for name in ("active", "unacknowledged", "shelved"):
        assert f"softplc_alarms_{name}" in figures
    for name in ("softplc_opcua_sessions", "softplc_opcua_subscriptions", "softplc_modbus_connections", "softplc_hmi_clients",
                 "process_cpu_seconds_total"):
        assert name in figures, name


async def test_figures_follow_real_clients_of_every_protocol(runtime: Runtime) -> None:
    hmi, opcua, modbus = adapter(runtime, "hmi"), adapter(runtime, "opcua"), adapter(runtime, "modbus")
    before = await scrape(hmi.url)
    opc = Client(opcua.endpoint, timeout=4)
    async with opc:
        subscription = await opc.create_subscription(100, None)
        await subscription.subscribe_data_change([opc.get_node(opcua.node_id("t01_iBL"))])
        modbus_client = AsyncModbusTcpClient("127.0.0.1", port=modbus.port, timeout=2, retries=0)
        await modbus_client.connect()
        try:
            first = min(mapping.address for mapping in modbus.map.mappings if mapping.table.value == "holding")
            assert not (await modbus_client.read_holding_registers(first, count=1, device_id=1)).isError()
            assert (await modbus_client.read_holding_registers(65000, count=1, device_id=1)).isError()  # illegal address
            async with client() as http, http.ws_connect(hmi.url + "api/live"):
                async with http.post(hmi.url + "api/login", json={"user": "engineer", "password": PASSWORDS["engineer"]}) as response:
                    csrf = (await response.json())["csrf"]
                for value in (20, 99999):  # one accepted, one out of range
                    async with http.post(hmi.url + "api/write", json={"tag": "t01_iFr", "value": value}, headers={"X-CSRF-Token": csrf}):
                        pass
                async with http.post(hmi.url + "api/commands/tags.force", json={"tag": "t02_iFr", "value": 5}, headers={"X-CSRF-Token": csrf}) as response:
                    assert response.status == 200
                await wait_until(lambda: runtime.db["t02_iFr"].forced, message="forced")
                during = await scrape(hmi.url)
                async with http.post(hmi.url + "api/commands/tags.unforce", json={"tag": "t02_iFr"}, headers={"X-CSRF-Token": csrf}):
                    pass
        finally:
            modbus_client.close()

    def grew(name: str, by: float = 1) -> bool:
        return during.get(name, 0) - before.get(name, 0) >= by

    assert during["softplc_opcua_sessions"] >= 1 and during["softplc_opcua_subscriptions"] >= 1 and during["softplc_opcua_monitored_items"] >= 1
    assert during["softplc_modbus_connections"] >= 1
    assert grew('softplc_modbus_requests_total{function="3",result="ok"}') and grew('softplc_modbus_requests_total{function="3",result="exception"}')
    assert grew('softplc_writes_total{result="accepted",source="hmi"}') and grew('softplc_writes_total{result="out_of_range",source="hmi"}')
    assert grew('softplc_commands_total{command="tags.force",result="accepted"}')
    assert during["softplc_forced_tags"] == 1
    assert during["softplc_hmi_clients"] >= 1 and during["softplc_hmi_sessions"] >= 1


async def test_histograms_keep_growing_across_a_reset_of_the_statistics(runtime: Runtime) -> None:
    url = adapter(runtime, "hmi").url
    task = runtime.tasks[0]
    label = f'task="{task.name}"'
    first = await scrape(url)
    cycles = task.stats.cycles
    await wait_until(lambda: task.stats.cycles >= cycles + 2, message="more cycles")
    task.stats.reset()  # what writing _sys.reset_stats does
    await wait_until(lambda: task.stats.cycles >= 2, message="cycles after the reset")
    second = await scrape(url)
    for name in ("scan", "cycle", "start_latency"):
        key = f"softplc_task_{name}_seconds_count{{{label}}}"
        assert second[key] >= first[key] + 2, name  # never down: Prometheus counters are monotonic
    buckets = sorted((float(key.split('le="')[1].split('"')[0]), value) for key, value in second.items()
                     if key.startswith("softplc_task_scan_seconds_bucket") and label in key)
    counts = [value for _, value in buckets]
    assert counts == sorted(counts) and counts[-1] == second[f"softplc_task_scan_seconds_count{{{label}}}"]


async def test_a_histogram_bins_only_new_samples_and_scales_a_window_overrun() -> None:
    series = TimingSeries(window=4)
    histogram = SeriesHistogram((0.001, 0.01))
    for value in (0.0005, 0.001, 0.005):
        series.add(value)
    histogram.update(series, resets=0)
    assert histogram.buckets() == [("0.001", 2.0), ("0.01", 3.0), ("+Inf", 3.0)] and histogram.sum == pytest.approx(0.0065)
    for _ in range(8):  # 8 new samples, a window of 4: its distribution stands for all 8
        series.add(0.5)
    histogram.update(series, resets=0)
    assert histogram.buckets() == [("0.001", 2.0), ("0.01", 3.0), ("+Inf", 11.0)] and histogram.sum == pytest.approx(4.0065)
    series.reset()
    series.add(0.002)
    histogram.update(series, resets=1)  # reset: the one sample since is new
    assert histogram.buckets() == [("0.001", 2.0), ("0.01", 4.0), ("+Inf", 12.0)]


async def test_who_may_scrape_a_token_a_login_or_nobody_else(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, start=False)
    settings = MetricsSettings(anonymous_loopback=False, token_file=Path("metrics.token"))
    plant.hmi.metrics_route.settings = settings  # who may scrape is the HMI's (servers.hmi.metrics)
    plant.runtime.adapters.insert(0, MetricsAdapter())
    await plant.runtime.start()
    try:
        token_file = tmp_path / "state" / "metrics.token"
        assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
        token = token_file.read_text().strip()
        assert len(token) >= 32
        async with aiohttp.ClientSession() as http:
            for headers in ({}, {"Authorization": "Bearer not-the-token"}, {"Authorization": f"Basic {token}"}):
                async with http.get(plant.url + "metrics", headers=headers) as response:
                    assert response.status == 401, headers
                    assert response.headers["WWW-Authenticate"] == 'Bearer realm="softplc metrics"'
        figures = await scrape(plant.url, Authorization=f"Bearer {token}")
        assert figures["softplc_tags"] == len(plant.db)
        async with client() as http:
            async with http.post(plant.url + "api/login", json={"user": "viewer", "password": PASSWORDS["viewer"]}) as response:
                assert response.status == 200
            assert (await scrape(plant.url, http))["softplc_tags"] == len(plant.db)  # a person logged in to the HMI
    finally:
        await plant.stop()


async def test_anonymous_scrapes_from_loopback_by_default_and_a_broken_adapter_is_left_out(tmp_path: Path) -> None:
    class Broken:
        name = "broken"

        async def start(self, runtime: Any) -> None: ...

        async def stop(self) -> None: ...

        def describe(self) -> str:
            return "broken"

        def metrics(self) -> dict[str, Any]:
            raise RuntimeError("a bug in an adapter")

    plant = await start_plant(tmp_path, start=False)
    plant.runtime.adapters.insert(0, MetricsAdapter())
    plant.runtime.add_adapter(Broken())
    await plant.runtime.start()
    try:
        figures = await scrape(plant.url)
        assert figures["softplc_tags"] == len(plant.db) and figures["softplc_hmi_clients"] == 0
        assert not any(key.startswith("softplc_broken") for key in figures)
    finally:
        await plant.stop()


async def test_mistakes_in_the_metrics_settings_are_located_problems(tmp_path: Path) -> None:
    from hmi_support import plant_yaml, write_plant

    from softplc.config.yamlsource import ConfigError

    text = plant_yaml().replace("    port: 0\n", "    port: 0\n    metrics: {anonymous: everyone, token_file: \"\"}\n")
    with pytest.raises(ConfigError) as raised:
        load_config(write_plant(tmp_path, text))
    messages = [str(problem) for problem in raised.value.problems]
    assert [m.split(": ", 1)[1] for m in messages] == ["unknown value 'everyone' for 'anonymous'; expected one of: loopback, off"], messages
    text = plant_yaml().replace("    port: 0\n", "    port: 0\n    metrics: {token_file: \"\"}\n")
    with pytest.raises(ConfigError) as raised:
        load_config(write_plant(tmp_path, text))
    assert [str(p).split(": ", 1)[1] for p in raised.value.problems] == [
        "token_file is empty: name a file (e.g. metrics.token) or leave the key out"], raised.value.problems
    config = load_config(write_plant(tmp_path, plant_yaml().replace("    port: 0\n", "    port: 0\n    metrics: {enabled: false}\n")))
    assert [adapter.name for adapter in build_adapters(config, argparse.Namespace(hmi_port=0)) if adapter.name in ("hmi", "metrics")] == ["hmi"]
