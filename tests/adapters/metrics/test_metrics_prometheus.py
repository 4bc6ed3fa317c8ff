"""A real Prometheus server (Debian's `prometheus` package) scrapes a running plant's /metrics.

The scrape configuration is the one docs/operations.md gives (a bearer token file, anonymous
scrapes off); Prometheus listens on a free loopback port with a temporary TSDB. Its own API then
says that the target is up and that a softplc metric has the value the runtime has.
"""

from __future__ import annotations

import asyncio
import shutil
import socket
import time
from pathlib import Path
from typing import Any

import aiohttp
from hmi_support import start_plant
from tools_support import missing

from softplc.adapters.hmi.metrics_settings import MetricsSettings
from softplc.adapters.metrics.adapter import MetricsAdapter

PROMETHEUS = shutil.which("prometheus") or ""
if not PROMETHEUS:
    missing("Debian's prometheus is not installed (scripts/install-test-tools.sh)", module=True)

SCRAPE_CONFIG = """
global:
  scrape_interval: 1s
  scrape_timeout: 1s
scrape_configs:
  - job_name: softplc
    metrics_path: /metrics
    authorization:
      credentials_file: {token}
    static_configs:
      - targets: ["127.0.0.1:{port}"]
"""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


async def ask(http: aiohttp.ClientSession, url: str, **params: str) -> Any:
    async with http.get(url, params=params) as response:
        body = await response.json()
        assert body["status"] == "success", body
        return body["data"]


async def test_a_prometheus_server_scrapes_the_plant(tmp_path: Path) -> None:
    plant = await start_plant(tmp_path / "plant", start=False)
    settings = MetricsSettings(anonymous_loopback=False, token_file=Path("metrics.token"))
    plant.hmi.metrics_route.settings = settings  # who may scrape is the HMI's (servers.hmi.metrics)
    plant.runtime.adapters.insert(0, MetricsAdapter())
    await plant.runtime.start()
    port = free_port()
    config = tmp_path / "prometheus.yml"
    config.write_text(SCRAPE_CONFIG.format(token=tmp_path / "plant" / "state" / "metrics.token", port=plant.hmi.port))
    log = (tmp_path / "prometheus.log").open("wb")
    server = await asyncio.create_subprocess_exec(
        PROMETHEUS, f"--config.file={config}", f"--storage.tsdb.path={tmp_path / 'tsdb'}", f"--web.listen-address=127.0.0.1:{port}",
        "--log.level=warn", stdout=log, stderr=log)
    api = f"http://127.0.0.1:{port}/api/v1/"
    try:
        async with aiohttp.ClientSession() as http:
            deadline = time.monotonic() + 30
            target: dict[str, Any] = {}
            while target.get("health") != "up":
                assert time.monotonic() < deadline, f"target not up: {target} ({(tmp_path / 'prometheus.log').read_text()[-2000:]})"
                assert server.returncode is None, (tmp_path / "prometheus.log").read_text()
                await asyncio.sleep(0.25)
                try:
                    targets = (await ask(http, api + "targets"))["activeTargets"]
                except (aiohttp.ClientConnectionError, aiohttp.ContentTypeError):
                    continue  # not listening yet, or listening but not ready (503, plain text)
                target = targets[0] if targets else {}
            assert target["scrapeUrl"] == f"http://127.0.0.1:{plant.hmi.port}/metrics" and target["lastError"] == ""
            result = (await ask(http, api + "query", query="softplc_tags"))["result"]
            assert [(sample["metric"]["job"], float(sample["value"][1])) for sample in result] == [("softplc", float(len(plant.db)))]
            cycles = (await ask(http, api + "query", query='softplc_task_scan_seconds_count{task="fast"}'))["result"]
            assert float(cycles[0]["value"][1]) > 0
    finally:
        if server.returncode is None:
            server.terminate()
            try:
                await asyncio.wait_for(server.wait(), 10)
            except asyncio.TimeoutError:
                server.kill()
                await server.wait()
        log.close()
        await plant.stop()
