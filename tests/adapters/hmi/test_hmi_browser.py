"""The HMI in real headless Chromium (Debian's, driven by Playwright) against a real runtime.

One browser for the module, one runtime (HMI + Modbus + OPC UA on free ports) for most tests.
A failed test leaves a screenshot in tests/artifacts/hmi/. Every page is also photographed at
1280x800 and 390x844 (phone) into the same folder, for people to look at.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from hmi_support import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
    SCRIPT_DESCRIPTION,
    Plant,
    browser,
    log_in,
    open_page,
    plant_yaml,
    ready,
    require_browser,
    screenshot_on_failure,
    start_plant,
    wait_until,
)

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_plant(tmp_path_factory.mktemp("hmi-browser"), modbus=True, opcua=True)
    yield plant
    await plant.stop()


async def test_robot_markers_follow_their_position_tags(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "robot-markers"):
        await ready(page)
        for x, y in ((12.0, 3.0), (4.5, 6.5)):
            plant.drive(r01_xpos=x, r01_ypos=y, r01_navstate="moving")
            await page.wait_for_function(
                "([x, y]) => { const m = document.querySelector('.floor .robot[data-robot=\"r01\"]');"
                " return m && Math.abs(m.dataset.x - x) < 0.02 && Math.abs(m.dataset.y - y) < 0.02; }", arg=[x, y])
        # The marker is drawn where the map puts (4.5, 6.5): 40 SVG units per metre, y upwards.
        transform = await page.get_attribute(".floor .robot[data-robot='r01']", "transform")
        assert transform == f"translate({4.5 * 40:.1f} {(8.6 - 6.5) * 40:.1f})"
        assert await page.get_attribute(".floor .robot[data-robot='r01'] .ring", "class") == "ring moving"
        assert not errors, errors
    await context.close()


async def test_a_buffer_bar_follows_a_modbus_write(browser: Any, plant: Plant) -> None:
    from pymodbus.client import AsyncModbusTcpClient

    modbus = plant.adapters["modbus"]
    context, page, _ = await open_page(browser, plant.url + "#/overview")
    client = AsyncModbusTcpClient("127.0.0.1", port=modbus.port, timeout=2, retries=0)
    async with screenshot_on_failure(page, "buffer-bar"):
        await ready(page)
        await client.connect()
        response = await client.write_register(modbus.map.by_tag["t01_iBM"].address, 60)
        assert not response.isError()
        # iBM → the plant's program computes iBL = 60 % → the station's bar and the task card follow.
        await page.wait_for_selector(".station[data-task='t01'][data-kind='in'] .bar-fill[data-level='60.0']")
        assert await page.get_attribute(".station[data-task='t01'][data-kind='in'] .bar-fill", "height") == f"{68 * 0.6:.1f}"
        await page.wait_for_function("() => document.querySelector('.task-card[data-task=\"t01\"] .level .label')?.textContent.includes('60 / 100 items')")
        await client.write_register(modbus.map.by_tag["t01_iBM"].address, 0)
    client.close()
    await context.close()


async def test_a_viewer_cannot_write(browser: Any, plant: Plant) -> None:
    context, page, _ = await open_page(browser, plant.url + "#/tags?q=limit")
    async with screenshot_on_failure(page, "viewer-cannot-write"):
        await ready(page)
        await page.wait_for_selector(".vrow[data-tag='limit']")
        assert await page.locator("[data-write]").count() == 0  # no write control for a viewer
        await page.goto(plant.url + "#/tasks")
        await ready(page)
        assert await page.locator("[data-command]").count() == 0  # no reset buttons either
        # A mimic button that writes: the viewer is told, nothing is written.
        await page.goto(plant.url + "#/view/test")
        await ready(page)
        await page.click("#button")
        await page.wait_for_selector("dialog[open] >> text=You may not write limit")
        assert plant.db.value("limit") != 42.0
    await context.close()


async def test_an_operators_write_is_confirmed_and_read_back_over_opc_ua(browser: Any, plant: Plant) -> None:
    from asyncua import Client

    opcua = plant.adapters["opcua"]
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=t01_iFr")
    async with screenshot_on_failure(page, "operator-write"):
        await ready(page)
        await log_in(page, "operator")
        await page.click("[data-write='t01_iFr']")
        await page.fill("#write-value", "12.5")
        await page.click("dialog button[type=submit]")  # Review
        change = page.locator("dialog .change")
        await change.wait_for()
        assert (await change.text_content()) == "30 items/min→12.5 items/min"
        assert plant.db.value("t01_iFr") == 30.0  # nothing written before the confirmation
        await page.click("dialog button[type=submit]")  # Confirm write
        await page.wait_for_selector("dialog .done")
        async with Client(opcua.endpoint, timeout=4) as client:
            node = client.get_node(opcua.node_id("t01_iFr"))
            for _ in range(200):
                if await node.read_value() == 12.5:
                    break
                await asyncio.sleep(0.02)
            assert await node.read_value() == 12.5
        assert not errors, errors
    plant.drive(t01_iFr=30.0)
    await context.close()


async def test_a_robots_details_are_live_and_writable_by_an_operator(browser: Any, plant: Plant) -> None:
    context, page, _ = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "robot-details"):
        await ready(page)
        await log_in(page, "operator")
        await ready(page)
        await page.click(".robot-card[data-robot='r02']")
        row = page.locator("dialog[open] tr[data-tag='r02_xpos']")
        plant.drive(r02_xpos=11.25)
        await page.wait_for_function("() => document.querySelector('dialog[open] tr[data-tag=\"r02_xpos\"] .live-value')?.textContent === '11.25 m'")
        assert await row.locator("button").count() == 0  # read-only for an operator
        await page.click("dialog[open] tr[data-tag='r02_tcurr'] button")
        await page.fill("#write-value", "2")
        await page.click("dialog button[type=submit]")
        await page.click("dialog button[type=submit]")
        await page.wait_for_selector("dialog .done")
        await wait_until(lambda: plant.db.value("r02_tcurr") == 2, message="r02_tcurr written")
    await context.close()


async def test_an_out_of_range_write_shows_the_rule_it_broke(browser: Any, plant: Plant) -> None:
    context, page, _ = await open_page(browser, plant.url + "#/tags?q=t01_iFr")
    async with screenshot_on_failure(page, "out-of-range"):
        await ready(page)
        await log_in(page, "operator")
        await page.click("[data-write='t01_iFr']")
        await page.fill("#write-value", "99999")
        await page.click("dialog button[type=submit]")
        await page.click("dialog button[type=submit]")
        refusal = page.locator("dialog .refusal")
        await refusal.wait_for()
        assert await refusal.get_attribute("data-rule") == "out of range"
        assert (await refusal.text_content()) == "Refused — out of range: 99999.0 is above the maximum 6000"
        assert plant.db.value("t01_iFr") == 30.0
    await context.close()


async def test_a_user_mimic_follows_its_tags(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/view/test")
    async with screenshot_on_failure(page, "user-mimic"):
        await ready(page)
        plant.drive(t01_iBM=90, t02_iBM=5, r01_xpos=3.0, r01_ypos=2.0)
        await page.wait_for_function("() => document.querySelector('#items_span')?.textContent === '90 pcs'")
        await page.wait_for_function("() => document.querySelector('#sum')?.textContent === '95'")  # a server-side expression
        await page.wait_for_function("() => document.querySelector('#level')?.dataset.share === '0.9000'")
        assert await page.get_attribute("#level", "height") == str(96 * 0.9)
        assert await page.eval_on_selector("#level", "node => node.style.fill") == "rgb(179, 38, 30)"  # above the 80 threshold
        assert await page.is_visible("#alarm")  # visible: t01_iBL >= 80
        await page.wait_for_function("() => document.querySelector('#robot')?.getAttribute('transform') === 'translate(230.00 170.00)'")
        plant.drive(t01_iBM=10)
        await page.wait_for_function("() => document.querySelector('#alarm')?.style.display === 'none'")
        # The drawing's own script and handler never ran.
        assert await page.evaluate("() => window.__pwned") is None
        assert await page.locator(".mimic-host script").count() == 0
        assert not errors, errors
    await context.close()


async def test_a_script_in_a_description_is_shown_as_text(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=note")
    async with screenshot_on_failure(page, "script-as-text"):
        await ready(page)
        description = page.locator(".vrow[data-tag='note'] .d")
        await description.wait_for()
        assert await description.text_content() == SCRIPT_DESCRIPTION
        assert await page.locator(".vrow[data-tag='note'] img, .vrow[data-tag='note'] b, .vrow[data-tag='note'] script").count() == 0
        assert await page.text_content("#plant-name") == "hmi <b>test</b> plant"
        await asyncio.sleep(0.2)
        assert await page.evaluate("() => window.__pwned") is None
        assert not errors, errors
    await context.close()


async def test_the_page_says_disconnected_when_the_runtime_stops_and_recovers_when_it_returns(browser: Any, tmp_path: Path) -> None:
    first = await start_plant(tmp_path)  # heartbeat 2 s: the page must notice the closed socket, not a missed heartbeat
    port = first.hmi.port
    context, page, _ = await open_page(browser, first.url + "#/overview")
    second = None
    async with screenshot_on_failure(page, "disconnected"):
        try:
            await ready(page)
            await page.wait_for_selector("#connection.ok")
            await first.stop()
            await page.wait_for_selector("#offline:not([hidden])", timeout=3000)  # at once, not after a timeout
            assert "Disconnected from the runtime" in await page.text_content("#offline")
            assert await page.text_content("#connection") == "disconnected"
            assert await page.evaluate("() => document.body.classList.contains('offline')")
            second = await start_plant(tmp_path, port=port)
            second.drive(r02_xpos=15.0)
            await page.wait_for_selector("#connection.ok", timeout=15000)
            assert await page.is_hidden("#offline")
            await page.wait_for_function("() => Math.abs(document.querySelector('.floor .robot[data-robot=\"r02\"]')?.dataset.x - 15) < 0.02")
        finally:
            if second is not None:
                await second.stop()
    await context.close()


async def test_a_program_fault_shows_with_its_error_and_an_operator_resets_it(browser: Any, plant: Plant) -> None:
    context, page, _ = await open_page(browser, plant.url + "#/tasks")
    async with screenshot_on_failure(page, "program-fault"):
        await ready(page)
        state = page.locator("[data-program='faulty'] .chip")
        await page.wait_for_function("() => document.querySelector('[data-program=\"faulty\"] .chip')?.textContent === 'RUNNING'")
        plant.drive(flag=True)
        await page.wait_for_function("() => document.querySelector('[data-program=\"faulty\"] .chip')?.textContent === 'FAULTED'")
        assert "RuntimeError: tripped by the test" in await page.text_content("[data-program='faulty'] .error-text")
        assert await page.locator("[data-command]").count() == 0  # a viewer may not reset
        plant.drive(flag=False)
        await log_in(page, "operator")
        await page.click("[data-command='reset_faults']")
        await page.wait_for_selector("dialog .change >> text=→true")
        await page.click("dialog button[type=submit]")
        await page.wait_for_selector("dialog .done")
        await page.wait_for_function("() => document.querySelector('[data-program=\"faulty\"] .chip')?.textContent === 'RUNNING'")
        assert await state.get_attribute("class") == "chip ok"
    await context.close()


BANNER_JS = "export function mount(node) { node.className = 'error-banner'; node.textContent = 'ALARM: a banner of another module'; }"
PAGE_JS = "export function mount(root, ctx) { root.textContent = `extra page for ${ctx.session.role}`; root.dataset.ready = '1'; }"


async def test_other_modules_add_pages_banners_and_routes(browser: Any, tmp_path: Path) -> None:
    """The shell other issues build on: a page in the navigation, a banner on every page, routes of their own."""
    from aiohttp import web

    from softplc.adapters.hmi.shell import Page
    from softplc.core.roles import Role

    def script(text: str) -> Any:
        async def handler(request: web.Request) -> web.Response:
            return web.Response(text=text, content_type="text/javascript")

        return handler

    plant = await start_plant(tmp_path, start=False)
    plant.hmi.shell.add_page(Page("extra", "Extra", "/ext/page.js", order=50))
    plant.hmi.shell.add_page(Page("secret", "Engineering", "/ext/page.js", order=51, min_role=Role.ENGINEER))
    plant.hmi.shell.add_banner("/ext/banner.js")
    plant.hmi.shell.add_routes([web.get("/ext/banner.js", script(BANNER_JS)), web.get("/ext/page.js", script(PAGE_JS))])
    await plant.runtime.start()
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "extensions"):
        try:
            await ready(page)
            assert (await page.inner_text("#banners")).strip() == "ALARM: a banner of another module"  # the forced banner is there, hidden
            assert await page.locator("#nav a[data-page='secret']").count() == 0  # not for a viewer
            await page.click("#nav a[data-page='extra']")
            await page.wait_for_selector("main[data-page='extra'][data-ready='1']")
            assert await page.text_content("main") == "extra page for viewer"
            assert (await page.inner_text("#banners")).strip() == "ALARM: a banner of another module"
            with pytest.raises(RuntimeError, match="add pages, banners and routes before runtime.start"):
                plant.hmi.shell.add_page(Page("late", "Late", "/ext/page.js"))
            assert not errors, errors
        finally:
            await plant.stop()
    await context.close()


PAGES = ("overview", "view/test", "tags", "tasks", "robots")


async def test_every_page_at_desktop_and_phone_width(browser: Any, plant: Plant) -> None:
    """No script error or CSP violation, nothing wider than a phone; screenshots for people to look at."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    for label, width, height in (("desktop", 1280, 800), ("phone", 390, 844)):
        context, page, errors = await open_page(browser, plant.url + "#/overview", width=width, height=height)
        for name in PAGES:
            async with screenshot_on_failure(page, f"page-{name.replace('/', '-')}-{label}-failed"):
                await page.goto(f"{plant.url}#/{name}")
                await ready(page)
                await asyncio.sleep(0.3)  # let values and markers settle for the picture
                await page.screenshot(path=str(ARTIFACTS / f"page-{name.replace('/', '-')}-{label}.png"), full_page=True)
                overflow = await page.evaluate("() => document.documentElement.scrollWidth - window.innerWidth")
                assert overflow <= 1, f"{name} is {overflow} px wider than a {width} px screen"
        assert not errors, errors
        await context.close()


async def test_the_tags_page_shows_10000_tags_and_subscribes_only_the_visible_rows(browser: Any, tmp_path: Path) -> None:
    plant = await start_plant(tmp_path, text=plant_yaml(blobs=9_999))  # with the others: over 10,000 tags
    context, page, errors = await open_page(browser, plant.url + "#/tags")
    async with screenshot_on_failure(page, "tags-10000"):
        try:
            await ready(page)
            await page.wait_for_selector(".vrow[data-tag]")
            total = len(plant.db)
            assert total > 10_000
            assert await page.text_content(".count") == f"{total:,} of {total:,} tags"
            assert await page.locator(".vbody .vrow").count() < 60  # rows in the page: only those in view

            def watched() -> set[str]:
                groups = [client.group for client in plant.hmi.hub.clients if client.group is not None]
                return set().union(*(group.members_of for group in groups)) if groups else set()

            await wait_until(lambda: "b0001_text" in watched() or "r01_xpos" in watched(), message="visible rows subscribed")
            assert len(watched()) < 60
            await page.eval_on_selector(".vbody", "body => { body.scrollTop = body.scrollHeight; }")
            await page.wait_for_selector(".vrow[data-tag='_sys.fast.level_t02.faults']")
            await wait_until(lambda: "_sys.fast.level_t02.faults" in watched() and "r01_xpos" not in watched(), message="resubscribed")
            plant.drive(b9999_text="seen live")
            await page.fill("input[type=search]", "b9999")
            await page.wait_for_function("() => document.querySelector('.vrow[data-tag=\"b9999_text\"] .live-value')?.textContent === 'seen live'")
            assert not errors, errors
        finally:
            await plant.stop()
    await context.close()
