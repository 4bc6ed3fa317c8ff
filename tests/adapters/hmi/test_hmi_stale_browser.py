"""The HMI without a live channel, in real headless Chromium: a dead runtime greys every value; a login page claims no outage.

Colour is judged from the pixels Chromium paints (an element's screenshot): a value drawn in
colour has many saturated, bright pixels; a stale one has none.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest
from hmi_support import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
    browser,
    log_in,
    open_page,
    ready,
    require_browser,
    screenshot_on_failure,
    start_plant,
)

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")

# What must grey when the runtime is gone, page by page: (page, selector, what it is).
LIVE_THINGS = [
    ("overview", "#runtime-state", "the header's runtime state"),
    ("overview", ".floor", "the factory map with its stations, bars and robots"),
    ("overview", ".task-card[data-task='t01'] .level .track", "a task card's level bar"),
    ("overview", ".robot-card[data-robot='r01'] .chip", "a robot's state chip"),
    ("overview", ".task-card[data-task='t01']", "a task card"),
    ("tags", ".vrow[data-tag='limit'] .qual", "the Tags page's quality"),
    ("tasks", ".panel .chip", "the Tasks page's runtime state"),
    ("tasks", "[data-program='count'] .chip", "a program's state"),
    ("robots", ".robot-panel[data-robot='r01'] .chip", "the Robots page's state chip"),
    ("view/test", ".mimic-host svg", "a user view"),
]


async def colourful_share(page: Any, selector: str) -> float:
    """The share of the element's pixels that are clearly coloured (saturated and bright)."""
    import numpy as np
    from PIL import Image

    picture = np.asarray(Image.open(io.BytesIO(await page.locator(selector).first.screenshot())).convert("HSV"))
    coloured = (picture[..., 1] > 70) & (picture[..., 2] > 90)
    return float(coloured.mean()) if coloured.size else 0.0


async def test_when_the_runtime_dies_every_live_value_greys_and_the_state_chip_says_unreachable(browser: Any, tmp_path: Path) -> None:
    first = await start_plant(tmp_path)
    port = first.hmi.port
    first.drive(r01_navstate="moving", r01_status=True, r01_tcurr=1, r01_currloc=1, t01_iBM=60, t02_iBM=30)
    context = await browser.new_context(viewport={"width": 1280, "height": 800})
    pages: dict[str, Any] = {}
    second = None
    try:
        for name in dict.fromkeys(page for page, _, _ in LIVE_THINGS):
            page = await context.new_page()
            await page.goto(f"{first.url}#/{name}" + ("?q=limit" if name == "tags" else ""))
            await ready(page)
            await page.wait_for_selector("#runtime-state.ok")
            pages[name] = page
        for name, selector, what in LIVE_THINGS:
            assert await colourful_share(pages[name], selector) > 0.01, f"{what} is not drawn in colour while live"
        await first.stop()
        for name, page in pages.items():
            async with screenshot_on_failure(page, f"stale-{name.replace('/', '-')}"):
                await page.wait_for_selector("#connection.bad", timeout=3000)
                assert (await page.text_content("#runtime-state")).lower() == "unreachable"
                assert "ok" not in (await page.get_attribute("#runtime-state", "class")).split()
        for name, selector, what in LIVE_THINGS:
            share = await colourful_share(pages[name], selector)
            assert share < 0.002, f"{what} keeps its colour ({share:.1%} coloured pixels) while the runtime is gone"
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        await pages["overview"].screenshot(path=str(ARTIFACTS / "stale-overview-desktop.png"))
        # Back: the values are fresh again, in colour, and the chip says RUNNING.
        second = await start_plant(tmp_path, port=port)
        second.drive(r01_navstate="moving", r01_status=True, r01_tcurr=1, r01_currloc=1, t01_iBM=60)
        overview = pages["overview"]
        await overview.wait_for_selector("#runtime-state.ok", timeout=15000)
        await ready(overview)
        await overview.wait_for_function("() => !document.body.classList.contains('offline')")
        assert await overview.text_content("#runtime-state") == "RUNNING"
        for selector in (".floor", "#runtime-state", ".robot-card[data-robot='r01'] .chip"):
            assert await colourful_share(overview, selector) > 0.01, f"{selector} stays grey after the runtime is back"
    finally:
        if second is not None:
            await second.stop()
        await context.close()


async def test_while_the_runtime_is_away_retries_do_not_flash_the_values_back_to_colour(browser: Any, tmp_path: Path) -> None:
    plant = await start_plant(tmp_path)
    context, page, _ = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "stale-retries"):
        try:
            await ready(page)
            await page.wait_for_selector("#runtime-state.ok")
            # Record every moment the page stops being marked stale, from the loss on.
            await page.evaluate("""() => {
                window.__fresh = [];
                new MutationObserver(() => { if (!document.body.classList.contains('offline')) window.__fresh.push(document.getElementById('connection').textContent); })
                  .observe(document.body, { attributes: true, attributeFilter: ['class'] });
            }""")
        finally:
            await plant.stop()
        await page.wait_for_selector("#connection.bad", timeout=3000)
        # Two reconnection attempts (0.5 s, then 1 s later) that fail.
        await page.wait_for_function("() => window.softplcHmi.live._retry >= 3", timeout=10000)
        assert await page.evaluate("() => window.__fresh") == []
        assert await page.text_content("#runtime-state") == "unreachable"
    await context.close()


async def test_a_login_page_does_not_claim_the_runtime_is_disconnected(browser: Any, tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, anonymous="off")
    context = await browser.new_context(viewport={"width": 1280, "height": 800})
    page = await context.new_page()
    # Note each time the red banner shows, from the first script of the page on.
    await page.add_init_script("""
        window.__banners = [];
        document.addEventListener('DOMContentLoaded', () => {
          const banner = document.getElementById('offline');
          new MutationObserver(() => { if (!banner.hidden) window.__banners.push(banner.textContent); })
            .observe(banner, { attributes: true, childList: true, characterData: true, subtree: true });
        });""")
    async with screenshot_on_failure(page, "login-page-not-disconnected"):
        try:
            await page.goto(plant.url)
            await page.wait_for_selector(".login-page")
            # The live channel's fate is settled: it is not opened before the login (the chip leaves "connecting…").
            await page.wait_for_function("() => document.getElementById('connection').textContent !== 'connecting…'")
            assert await page.is_hidden("#offline")
            assert await page.evaluate("() => window.__banners") == []
            assert await page.text_content("#connection") != "disconnected"
            assert "bad" not in (await page.get_attribute("#connection", "class")).split()
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            await page.screenshot(path=str(ARTIFACTS / "login-page-desktop.png"))
            await log_in(page, "viewer")
            await page.wait_for_selector("#connection.ok")
            await page.wait_for_selector("#runtime-state.ok")
            assert await page.evaluate("() => window.__banners") == []
            # Logging out brings the login page back, again without a claim of an outage.
            await page.click("#user-box button")
            await page.wait_for_selector(".login-page")
            await page.wait_for_function("() => document.getElementById('connection').textContent !== 'live'")
            assert await page.evaluate("() => window.__banners") == []
            assert await page.is_hidden("#offline")
        finally:
            await plant.stop()
    await context.close()
