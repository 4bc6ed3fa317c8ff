"""Operating the plant from the HMI in real headless Chromium (issue 17): forcing, program control,
online change, the audit page — against a real runtime with its audit trail.

The plant is the HMI tests' (hmi_support.py) plus a program of its own folder (ticker.py) that
an online change edits. Every new page and dialog is photographed at 1280x800 and 390x844 into
tests/artifacts/hmi/ (ops-*.png), for people to look at.
"""

from __future__ import annotations

import asyncio
import csv
import io
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from hmi_support import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
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

from softplc.core.roles import Role
from softplc.core.tagdb import Origin

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")
ENGINEER = Origin("test", "erin", role=Role.ENGINEER)

TICKER = '''
from softplc import InOut, Param, Program


class Ticker(Program):
    """Adds `step` to its counter every scan."""

    ticks = InOut("ticks so far")
    step = Param(1, "added per scan")

    def scan(self):
        self.ticks = (self.ticks + self.step) % 1000000
'''
TICKER_PROGRAM = """      - name: ticker
        program: ticker.py:Ticker
        bind: {ticks: ticks}
        params: {step: 1}
"""


def ops_plant() -> str:
    """The HMI tests' plant with the ticker program and its tag."""
    text = plant_yaml()
    tag, program = "  flag:    {type: bool}\n", "      - name: level_{task}\n"
    assert tag in text and program in text
    return text.replace(tag, tag + "  ticks:   {type: uint32, access: ro}\n").replace(program, TICKER_PROGRAM + program)


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    from softplc.adapters.audit.recorder import AuditRecorder
    from softplc.storage.audit.settings import AuditSettings

    folder = tmp_path_factory.mktemp("hmi-ops")
    (folder / "ticker.py").write_text(TICKER)
    plant = await start_plant(folder, text=ops_plant(), start=False)
    plant.runtime.adapters.insert(0, AuditRecorder(AuditSettings(section={"flush_period": "50ms"}), "hmi test plant"))
    await plant.runtime.start()
    yield plant
    await plant.stop()


def unexpected(errors: list[str]) -> list[str]:
    """Console errors but the browser's note of an answer the test expected to be a refusal (403, 422)."""
    return [error for error in errors if not error.startswith("Failed to load resource: the server responded with a status of 4")]


async def visible(page: Any, selector: str) -> bool:
    """Whether the element is shown (HTML `hidden`, SVG `visibility`)."""
    return await page.eval_on_selector(selector, "e => !e.closest('[hidden]') && getComputedStyle(e).visibility !== 'hidden' && getComputedStyle(e).display !== 'none'")


async def test_a_forced_tag_carries_an_f_on_every_page_and_a_banner_says_so(browser: Any, plant: Plant) -> None:
    await plant.runtime.commands.call("tags.force", {"tag": "t01_iBM", "value": 55}, ENGINEER)
    await wait_until(lambda: plant.db["t01_iBM"].forced, message="forced")
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "ops-forced-marks"):
        try:
            await ready(page)  # a visitor (viewer) sees all of it: forcing must be impossible to miss
            await page.wait_for_selector(".forced-banner[data-count='1']")
            assert await page.text_content(".forced-banner .forced-text") == "1 tag forced: t01_iBM = 55. Programs and clients cannot change it."
            await page.wait_for_function("() => !document.querySelector('.task-card[data-task=\"t01\"] .level .forced-mark').hidden")
            assert not await visible(page, ".task-card[data-task='t02'] .level .forced-mark")
            await page.wait_for_function("() => document.querySelector('.station[data-task=\"t01\"][data-kind=\"in\"] .forced-badge').getAttribute('visibility') === 'visible'")
            assert await page.get_attribute(".station[data-task='t01'][data-kind='out'] .forced-badge", "visibility") == "hidden"
            await page.goto(plant.url + "#/tags?q=t01_iBM")
            await ready(page)
            await page.wait_for_function("() => document.querySelector('.vrow[data-tag=\"t01_iBM\"] .forced-mark')?.hidden === false")
            await page.click(".vrow[data-tag='t01_iBM'] .n")  # its details
            await page.wait_for_function("() => document.querySelector('dialog[data-tag=\"t01_iBM\"] .forced-mark')?.hidden === false")
            assert await page.locator("dialog [data-force]").count() == 0  # a viewer may not force
            await page.keyboard.press("Escape")
            await page.goto(plant.url + "#/view/test")
            await ready(page)
            await page.wait_for_selector(".forced-badge[data-forced-for='items']")
            assert await visible(page, ".forced-badge[data-forced-for='items']")
            await page.click(".forced-banner a")
            await page.wait_for_selector("main[data-page='forced'] tr[data-tag='t01_iBM']")
            assert await page.locator("[data-unforce]").count() == 0
            await plant.runtime.commands.call("tags.unforce", {"tag": "t01_iBM"}, ENGINEER)
            await page.wait_for_selector(".forced-banner", state="hidden")
            await page.wait_for_selector("main[data-page='forced'] tr[data-tag='t01_iBM']", state="detached")
            assert not unexpected(errors), errors
        finally:
            if plant.db["t01_iBM"].forced:
                await plant.runtime.commands.call("tags.unforce", {"tag": "t01_iBM"}, ENGINEER)
    await context.close()


async def test_an_engineer_forces_and_unforces_from_a_tags_details(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=limit")
    async with screenshot_on_failure(page, "ops-force-details"):
        await ready(page)
        await log_in(page, "engineer")
        await page.wait_for_selector(".vrow[data-tag='limit']")
        before = plant.db.value("limit")
        await page.click(".vrow[data-tag='limit'] .n")
        await page.click("dialog [data-force='limit']")
        await page.fill("#force-value", "1000")
        await page.click("dialog form button[type=submit]")  # Review
        await page.click("dialog form button[type=submit]")  # Confirm force
        refusal = page.locator("dialog .refusal")
        await refusal.wait_for()
        assert await refusal.text_content() == "Refused — limit: out of range: 1000.0 is above the maximum 100"
        assert not plant.db["limit"].forced
        await page.fill("#force-value", "42")
        await page.click("dialog form button[type=submit]")
        change = page.locator("dialog .change")
        await change.wait_for()
        assert await change.text_content() == f"{before:g} bar→42 bar F"
        await page.screenshot(path=str(ARTIFACTS / "ops-force-dialog-desktop.png"))
        await page.click("dialog form button[type=submit]")
        await page.wait_for_selector("dialog .done >> text=Forced: limit forced to 42.0 from the next cycle.")
        await wait_until(lambda: plant.db["limit"].forced and plant.db.value("limit") == 42.0, message="forced")
        await page.click("dialog .close-x")  # back to the details: the mark and Unforce
        await page.wait_for_function("() => document.querySelector('dialog[data-tag=\"limit\"] .forced-mark')?.hidden === false")
        await page.click("dialog [data-unforce='limit']")
        await page.wait_for_selector("dialog .change >> text=42 bar")
        await page.check("dialog input[value=restore]")
        assert await page.text_content("dialog button[type=submit]") == "Confirm unforce and restore"
        await page.screenshot(path=str(ARTIFACTS / "ops-unforce-dialog-desktop.png"))
        await page.click("dialog button[type=submit]")
        await page.wait_for_selector("dialog .done >> text=limit unforced and restored from the next cycle.")
        await wait_until(lambda: not plant.db["limit"].forced and plant.db.value("limit") == before, message="restored")
        assert not unexpected(errors), errors
    await context.close()


async def test_a_page_with_a_forced_tag_subscribes_once_not_at_every_snapshot(browser: Any, plant: Plant) -> None:
    """The forced banner re-watches the forced tags when `_sys.forced` arrives: the same names must
    not be subscribed again (each subscribe costs a snapshot, which carries `_sys.forced` again)."""
    await plant.runtime.commands.call("tags.force", {"tag": "t02_iBM", "value": 12}, ENGINEER)
    context = await browser.new_context(viewport={"width": 1280, "height": 800})
    page = await context.new_page()
    sent: list[str] = []
    received: list[str] = []

    def socket(ws: Any) -> None:
        ws.on("framesent", lambda frame: sent.append(json.loads(frame)["type"]))
        ws.on("framereceived", lambda frame: received.append(json.loads(frame)["type"]))

    page.on("websocket", socket)
    try:
        await page.goto(plant.url + "#/overview")
        await ready(page)
        await page.wait_for_selector(".forced-banner:not([hidden])")
        subscribed, heard = sent.count("subscribe"), len(received)
        await wait_until(lambda: len(received) >= heard + 10, timeout=10, message="ten more messages on the live channel")
        assert sent.count("subscribe") == subscribed, sent
    finally:
        await context.close()
        await plant.runtime.commands.call("tags.unforce", {"tag": "t02_iBM"}, ENGINEER)


async def test_viewers_and_operators_get_no_controls_and_the_api_refuses_them(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=limit")
    async with screenshot_on_failure(page, "ops-operator"):
        await ready(page)
        await log_in(page, "operator")
        await page.wait_for_selector(".vrow[data-tag='limit']")
        await page.click(".vrow[data-tag='limit'] .n")
        await page.wait_for_selector("dialog[data-tag='limit'] button >> text=Write…")  # an operator writes ...
        assert await page.locator("dialog [data-force]").count() == 0  # ... but does not force
        await page.keyboard.press("Escape")
        await page.goto(plant.url + "#/tasks")
        await ready(page)
        assert await page.locator("[data-action], [data-online-change]").count() == 0
        assert "need the engineer role" in await page.text_content("main")
        assert await page.locator("#nav a[data-page='audit']").count() == 0 and await page.locator("#nav a[data-page='forced']").count() == 1
        # The API answers an operator's call as it answers every path: the role check refuses it.
        status = await page.evaluate("""async () => {
            const session = await (await fetch('/api/session')).json();
            const answer = await fetch('/api/commands/programs.stop', {method: 'POST', headers: {'Content-Type': 'application/json',
              'X-CSRF-Token': session.csrf}, body: JSON.stringify({program: 'ticker'})});
            return [answer.status, (await answer.json()).error];
        }""")
        assert status == [403, "role operator may not stop programs"]
        assert plant.runtime.program("ticker").state.value == "RUNNING"
        assert not unexpected(errors), errors
    await context.close()


async def test_an_engineer_stops_and_starts_a_program_from_the_tasks_page(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/tasks")
    async with screenshot_on_failure(page, "ops-program-control"):
        await ready(page)
        await log_in(page, "engineer")
        await page.wait_for_selector("[data-program='ticker'] [data-action='stop']:not([disabled])")
        assert await page.is_disabled("[data-program='ticker'] [data-action='start']")
        await page.click("[data-program='ticker'] [data-action='stop']")
        await page.wait_for_selector("dialog >> text=its outputs take its fault reaction (hold)")
        assert plant.runtime.program("ticker").state.value == "RUNNING"  # nothing before the confirmation
        await page.click("dialog button[type=submit]")
        await page.wait_for_selector("dialog .done >> text=stopped program ticker: its outputs hold their values")
        await page.keyboard.press("Escape")
        await page.wait_for_function("() => document.querySelector('[data-program=\"ticker\"] .chip')?.textContent === 'STOPPED'")
        assert plant.runtime.program("ticker").state.value == "STOPPED"
        assert "Stopped: stopped program ticker" in await page.text_content("[data-program='ticker'] .program-result")
        await page.wait_for_selector("[data-program='ticker'] [data-action='start']:not([disabled])")
        await page.click("[data-program='ticker'] [data-action='start']")
        await page.click("dialog button[type=submit]")
        await page.wait_for_selector("dialog .done >> text=started program ticker")
        await page.keyboard.press("Escape")
        await page.wait_for_function("() => document.querySelector('[data-program=\"ticker\"] .chip')?.textContent === 'RUNNING'")
        ticks = plant.db.value("ticks")
        await wait_until(lambda: plant.db.value("ticks") > ticks, message="ticking again")
        assert not unexpected(errors), errors
    await context.close()


async def test_an_online_change_is_checked_then_applied_and_a_broken_one_is_refused_with_its_location(browser: Any, plant: Plant) -> None:
    path = plant.runtime.config.path
    module = path.parent / "ticker.py"
    original, source = path.read_text(), module.read_text()
    context, page, errors = await open_page(browser, plant.url + "#/tasks")
    async with screenshot_on_failure(page, "ops-online-change"):
        try:
            await ready(page)
            await log_in(page, "engineer")
            path.write_text(original.replace("params: {step: 1}", "params: {step: 7}"))
            await page.click("[data-online-change='check']")
            await page.wait_for_selector("dialog .change-list li >> text=program ticker: params")
            assert plant.runtime.program("ticker").params == {"step": 1}  # checked, not applied
            await page.screenshot(path=str(ARTIFACTS / "ops-online-change-check-desktop.png"))
            await page.click("[data-online-change='apply']")
            await page.wait_for_selector("dialog .done >> text=online change 1 applied: ticker")
            assert plant.runtime.program("ticker").params == {"step": 7}
            await page.keyboard.press("Escape")
            await page.wait_for_selector(".online-result >> text=online change 1 applied: ticker")
            await page.wait_for_selector("[data-program='ticker'] .version >> text=version 2")
            ticks = plant.db.value("ticks")
            await wait_until(lambda: plant.db.value("ticks") >= ticks + 14, message="ticking by 7")
            # A broken module: the check shows where, and nothing is applied.
            module.write_text(source.replace("self.ticks = (self.ticks + self.step)", "self.ticks = (self.ticks + self.step"))
            await page.click("[data-online-change='check']")
            problem = page.locator("dialog .change-list.problems li")
            await problem.first.wait_for()
            text = await problem.first.text_content()
            assert "ticker.py:" in text and "SyntaxError" in text, text
            assert await page.text_content("dialog [role=status]") == "Check refused — nothing applied."
            assert await page.locator("[data-online-change='apply']:visible").count() == 0
            await page.screenshot(path=str(ARTIFACTS / "ops-online-change-refused-desktop.png"))
            await page.keyboard.press("Escape")
            assert "Online change refused, nothing applied" in await page.text_content(".online-result")
            assert plant.runtime.program("ticker").version == 2 and plant.runtime.program("ticker").state.value == "RUNNING"
            assert not unexpected(errors), errors
        finally:
            path.write_text(original)
            module.write_text(source)
    await context.close()


async def test_the_audit_page_shows_an_hmi_write_and_filters_refusals(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=limit")
    async with screenshot_on_failure(page, "ops-audit"):
        await ready(page)
        await log_in(page, "operator")
        for value in ("17.5", "500"):  # one accepted, one out of range
            await page.click("[data-write='limit']")
            await page.fill("#write-value", value)
            await page.click("dialog button[type=submit]")
            await page.click("dialog button[type=submit]")
            await page.wait_for_selector("dialog .done, dialog .refusal")
            await page.keyboard.press("Escape")
        await page.click("#user-box button")  # log out
        await page.wait_for_selector("#user-box .who[data-role='viewer']")
        await log_in(page, "engineer")
        await page.click("#nav a[data-page='audit']")
        await ready(page)
        await page.fill("input[name=subject]", "limit")
        await page.select_option("select[name=source]", "hmi")
        await page.click("form.audit-filters button[type=submit]")
        await page.wait_for_selector("tr[data-name='limit'] >> text=17.5")
        rows = await page.eval_on_selector_all("tbody tr[data-name='limit']", "rows => rows.map(r => [...r.cells].map(c => c.textContent))")
        assert rows[0][1:3] == ["hmi", "operator"] and rows[0][4:] == ["limit", "17.5", "500", "refused: out of range: 500.0 is above the maximum 100"]
        assert rows[1][1:3] == ["hmi", "operator"] and rows[1][4:] == ["limit", "0", "17.5", "accepted"]
        await page.check("input[name=refused]")
        await page.click("form.audit-filters button[type=submit]")
        await page.wait_for_function("() => document.querySelectorAll('tbody tr[data-name=\"limit\"]').length === 1")
        href = await page.get_attribute("[data-export=csv]", "href")
        assert href == "/api/audit.csv?tag=limit&source=hmi&result=refused"
        async with page.expect_download() as download_info:
            await page.click("[data-export=csv]")
        download = await download_info.value
        exported = list(csv.DictReader(io.StringIO(Path(await download.path()).read_text())))
        # What the page shows, and the commands acting on the tag (a refused force of an earlier test).
        assert {(row["kind"], row["name"], row["new"]) for row in exported if row["kind"] == "write"} == {("write", "limit", "500")}
        assert all(row["source"] == "hmi" and row["accepted"] == "False" and row["tag"] == "limit" for row in exported)
        assert not unexpected(errors), errors
    plant.drive(limit=0.0)
    await context.close()


SHOTS = ("forced", "audit", "tasks", "tags")


async def test_every_new_page_at_desktop_and_phone_width(browser: Any, plant: Plant) -> None:
    """No script error or CSP violation, nothing wider than a phone; screenshots for people to look at."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    await plant.runtime.commands.call("tags.force", {"tag": "t02_iFr", "value": 0}, ENGINEER)
    await plant.runtime.commands.call("tags.force", {"tag": "r01_xpos", "value": 12.5}, ENGINEER)
    try:
        for label, width, height in (("desktop", 1280, 800), ("phone", 390, 844)):
            context, page, errors = await open_page(browser, plant.url + "#/overview", width=width, height=height)
            await ready(page)
            await log_in(page, "engineer")
            for name in ("overview", *SHOTS):
                async with screenshot_on_failure(page, f"ops-{name}-{label}-failed"):
                    await page.goto(f"{plant.url}#/{name}{'?q=iFr' if name == 'tags' else ''}")
                    await ready(page)
                    await page.wait_for_selector(".forced-banner[data-count='2']")
                    await asyncio.sleep(0.3)  # let values settle for the picture
                    await page.screenshot(path=str(ARTIFACTS / f"ops-{name}-{label}.png"), full_page=True)
                    overflow = await page.evaluate("() => document.documentElement.scrollWidth - window.innerWidth")
                    assert overflow <= 1, f"{name} is {overflow} px wider than a {width} px screen"
            await page.goto(f"{plant.url}#/tasks")
            await ready(page)
            await page.click("[data-online-change='check']")
            await page.wait_for_function("() => !document.querySelector('dialog [role=status]')?.textContent.startsWith('Checking')")
            await page.screenshot(path=str(ARTIFACTS / f"ops-online-change-{label}.png"))
            await page.keyboard.press("Escape")
            await page.goto(f"{plant.url}#/forced")
            await ready(page)
            await page.click("[data-unforce='t02_iFr']")
            await page.wait_for_selector("dialog .change >> text=0 items/min")
            await page.screenshot(path=str(ARTIFACTS / f"ops-unforce-{label}.png"))
            await page.keyboard.press("Escape")
            assert not unexpected(errors), errors
            await context.close()
    finally:
        for tag in ("t02_iFr", "r01_xpos"):
            await plant.runtime.commands.call("tags.unforce", {"tag": tag, "restore": True}, ENGINEER)
