"""The links on the HMI's Tasks page, in real headless Chromium: each link's health, live, and its bound tags.

The page learns the links from the `links.list` query and follows the `_sys.links.NAME.*` tags
over the live channel (it imports nothing of the links adapter). The remote is pymodbus's own
server; stopping it must turn the link's state chip to "down" with the reason, starting it
again back to "up". Screenshots at 1280x800 and 390x844 go to tests/artifacts/hmi/.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import pytest
from hmi_support import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
    browser,
    open_page,
    ready,
    require_browser,
    screenshot_on_failure,
    start_plant,
)

from softplc.adapters.links.manifest import build
from tests.links_support import PymodbusRemote

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")


def plant(port: int) -> str:
    return textwrap.dedent(f"""
        plant: {{name: "linked <b>plant</b>"}}
        links:
          press: {{protocol: modbus, host: 127.0.0.1, port: {port}, period: 100ms, timeout: 1s, backoff_max: 1s}}
        tags:
          force: {{type: float32, link: {{name: press, source: "holding:0", type: int16, scale: 10}}}}
          level: {{type: float32, max: 100, link: {{name: press, source: "holding:1"}}}}
          setpoint: {{type: int16, link: {{name: press, source: "holding:10", direction: out}}}}
        tasks:
          main: {{interval: 10ms}}
        servers:
          opcua: {{enabled: false}}
          modbus: {{enabled: false}}
          hmi: {{host: 127.0.0.1, port: 0}}
        """)


async def test_the_tasks_page_shows_each_link_and_its_health_live(browser: Any, tmp_path: Path) -> None:
    remote = PymodbusRemote()
    await remote.start()
    remote.holding[0] = 123
    remote.holding[1:3] = [0x4348, 0]  # float32 200.0: above the level tag's max
    linked = await start_plant(tmp_path, text=plant(remote.port), start=False)
    for adapter in build(linked.runtime.config, None):
        linked.runtime.add_adapter(adapter)
    await linked.runtime.start()
    context, page, errors = await open_page(browser, linked.url + "#/tasks")
    try:
        async with screenshot_on_failure(page, "links-tasks"):
            await ready(page)
            row = page.locator("[data-panel='links'] tr[data-link='press']")
            await row.locator(".chip.ok", has_text="up").wait_for()
            assert "modbus 127.0.0.1:" in await row.inner_text()
            await row.locator("td.num", has_text="1").first.wait_for()  # one bound tag read is not good (level)
            await row.locator("summary").click()
            level = row.locator(".link-tags tr[data-tag='level']")
            await level.wait_for()
            assert "200.0 is above the maximum 100" in await level.inner_text()
            assert await row.locator(".link-tags tr[data-tag='force'] .chip.ok").inner_text() == "good"
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            await page.screenshot(path=str(ARTIFACTS / "links-tasks-1280.png"), full_page=True)
            await remote.stop()
            await row.locator(".chip.bad", has_text="down").wait_for()
            assert "closed" in await row.locator(".error-text").inner_text()
            await page.set_viewport_size({"width": 390, "height": 844})
            await page.screenshot(path=str(ARTIFACTS / "links-tasks-390.png"), full_page=True)
            await remote.start(remote.port)
            await row.locator(".chip.ok", has_text="up").wait_for(timeout=10_000)
            assert await page.locator("[data-panel='links'] b").count() == 0  # names are text, never markup
            assert not errors, errors
    finally:
        await context.close()
        await linked.stop()
        await remote.stop()
