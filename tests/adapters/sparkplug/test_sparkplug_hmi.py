"""The Tasks page shows the Sparkplug B edge node: connection, primary host, counters (Chromium via Playwright)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from softplc.adapters.sparkplug.edge_node import EdgeNode
from softplc.adapters.sparkplug.settings import SparkplugSettings
from softplc.protocols.mqtt_settings import MqttSettings
from tests.hmi_support import (  # noqa: F401
    ARTIFACTS,
    browser,
    open_page,
    plant_yaml,
    ready,
    require_browser,
    screenshot_on_failure,
    start_plant,
)

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")


async def test_the_tasks_page_shows_the_edge_node_and_its_primary_host(browser: Any, mosquitto, tmp_path: Path) -> None:
    text = plant_yaml() + f'mqtt: {{url: "mqtt://127.0.0.1:{mosquitto.port}"}}\nsparkplug: {{group_id: plant1, edge_node_id: line1, primary_host: scada}}\n'
    plant = await start_plant(tmp_path / "plant", text=text, start=False)
    config = plant.runtime.config
    plant.runtime.add_adapter(EdgeNode(SparkplugSettings.from_config(config), MqttSettings.from_config(config)))
    await plant.runtime.start()
    try:
        for width, height in ((1280, 800), (390, 844)):
            context, page, errors = await open_page(browser, plant.url + "#/tasks", width=width, height=height)
            async with screenshot_on_failure(page, f"sparkplug-tasks-{width}"):
                await ready(page)
                panel = page.locator("[data-panel='sparkplug']")
                await panel.locator(".chip", has_text="waiting for primary host").wait_for()
                assert await panel.locator("dd", has_text=f"mqtt://127.0.0.1:{mosquitto.port}").count() == 1
                assert await panel.locator("dd", has_text="plant1 / line1").count() == 1
                assert await panel.locator("dt", has_text="Primary host scada").count() == 1
                await panel.locator("dd", has_text="connected").first.wait_for()
                assert await panel.locator("dd.error-text", has_text="offline").count() == 1
                ARTIFACTS.mkdir(parents=True, exist_ok=True)
                await page.screenshot(path=str(ARTIFACTS / f"sparkplug-tasks-{width}.png"), full_page=True)
                assert errors == []
            await context.close()
    finally:
        await plant.stop()


async def test_a_plant_without_an_edge_node_has_no_panel(browser: Any, tmp_path: Path) -> None:
    plant = await start_plant(tmp_path / "plant")
    try:
        context, page, errors = await open_page(browser, plant.url + "#/tasks")
        await ready(page)
        assert await page.locator("[data-panel='sparkplug']").count() == 0 and errors == []
        await context.close()
    finally:
        await plant.stop()
