"""Alarms, the journal and trends in real headless Chromium against a real runtime on the simulated clock.

One browser and one runtime for the module (alarms, historian, Modbus and the HMI on free
ports), its clock simulated at 10x real time: a shelving of 30 s ends after 3 s, and the trend's
"now" is the runtime's, not the browser's. New pages are photographed at 1280x800 and 390x844
into tests/artifacts/hmi/ for people to look at; a failed test leaves a screenshot there.
"""

from __future__ import annotations

import asyncio
import logging
import shutil
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from hmi_supervisory_support import start_supervisory_plant
from hmi_support import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
    REPO,
    Plant,
    browser,
    log_in,
    open_page,
    ready,
    require_browser,
    screenshot_on_failure,
    wait_until,
)

from softplc.core.clock import SimClock

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")
SPEED = 10.0  # simulated seconds per real second


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_supervisory_plant(tmp_path_factory.mktemp("hmi-supervisory"), clock=SimClock(speed=SPEED))
    yield plant
    await plant.stop()


def engine(plant: Plant) -> Any:
    return plant.adapters["alarms"].engine


def state(plant: Plant, alarm: str) -> str:
    return engine(plant).get(alarm).state.value


async def raise_alarm(plant: Plant, task: str, items: int = 95) -> None:
    plant.drive(**{f"{task}_iBM": items})
    await wait_until(lambda: state(plant, f"{task}_input_full") == "unacknowledged", message=f"{task}_input_full active")


async def back_to_normal(plant: Plant) -> None:
    """Every alarm normal and acknowledged, nothing shelved: the next test starts clean."""
    commands = plant.runtime.commands
    for alarm in engine(plant).alarms:
        if alarm.shelving is not None:
            await commands.call("alarms.unshelve", {"alarm": alarm.name}, "test")
    plant.drive(t01_iBM=0, t02_iBM=0, flag=False)
    await wait_until(lambda: not engine(plant).active_count, message="alarms cleared")
    await commands.call("alarms.acknowledge_all", {}, "test")


async def test_the_alarm_banner_appears_when_a_modbus_write_pushes_a_level_over_its_limit(browser: Any, plant: Plant) -> None:
    from pymodbus.client import AsyncModbusTcpClient

    modbus = plant.adapters["modbus"]
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    client = AsyncModbusTcpClient("127.0.0.1", port=modbus.port, timeout=2, retries=0)
    async with screenshot_on_failure(page, "alarm-banner"):
        await ready(page)
        await page.wait_for_selector("#alarm-banner[data-level='none']")
        assert await page.text_content("#alarm-banner .ab-main") == "No alarms"
        await client.connect()
        response = await client.write_register(modbus.map.by_tag["t01_iBM"].address, 95)  # iBL = 95 % ≥ hi 90
        assert not response.isError()
        await page.wait_for_selector("#alarm-banner[data-level='high'][data-alarm='t01_input_full']")
        banner = page.locator("#alarm-banner")
        assert await banner.locator(".prio-text").text_content() == "High"  # the priority in words, not colour alone
        assert await banner.locator(".ab-message").text_content() == "input buffer of t01 at 95 %: send a robot"
        counts = {key: await banner.locator(f"[data-count='{key}'] b").text_content() for key in ("active", "unacknowledged", "shelved")}
        assert counts == {"active": "1", "unacknowledged": "1", "shelved": "0"}
        # A more severe alarm takes the banner.
        await client.write_register(modbus.map.by_tag["t02_iBM"].address, 100)
        await page.wait_for_selector("#alarm-banner[data-level='critical'][data-alarm='t02_input_full']")
        await page.wait_for_function("() => document.querySelector(\"#alarm-banner [data-count='active'] b\")?.textContent === '2'")
        await page.click("#alarm-banner .ab-link")  # the banner leads to the alarm page
        await page.wait_for_selector("main[data-page='alarms'] tr[data-alarm='t02_input_full'][data-state='unacknowledged']")
        assert not errors, errors
    client.close()
    await context.close()
    await back_to_normal(plant)


async def test_an_operator_acknowledges_from_the_summary_page_and_the_journal_shows_who(browser: Any, plant: Plant) -> None:
    await raise_alarm(plant, "t01")
    context, page, errors = await open_page(browser, plant.url + "#/alarms")
    async with screenshot_on_failure(page, "alarm-acknowledge"):
        await ready(page)
        await log_in(page, "operator")
        row = page.locator("tr[data-alarm='t01_input_full']")
        await row.locator("[data-action='acknowledge']").click()
        await page.wait_for_selector("tr[data-alarm='t01_input_full'][data-state='acknowledged']")
        assert await row.locator(".astate-text").text_content() == "Active, acknowledged"
        assert await row.locator("[data-action='acknowledge']").count() == 0
        assert "acknowledged t01_input_full" in await page.text_content(".action-status")
        await page.wait_for_selector("#alarm-banner[data-level='acknowledged']")
        assert state(plant, "t01_input_full") == "acknowledged"
        await page.click("#nav a[data-page='journal']")
        entry = page.locator("tr[data-alarm='t01_input_full'][data-transition='acknowledged']").first  # newest first
        await entry.wait_for()
        assert await entry.locator(".juser").text_content() == "operator (operator)"
        assert await entry.locator(".juser").get_attribute("title") == "hmi:operator@127.0.0.1"
        # Filters: operator actions of this user only.
        await page.select_option("#journal-transition", "actions")
        await page.fill("#journal-user", "operator")
        await page.wait_for_function("() => [...document.querySelectorAll('.journal-table tbody tr[data-transition]')].every(r => r.dataset.user === 'operator')"
                                     " && document.querySelectorAll('.journal-table tbody tr[data-transition]').length >= 1")
        href = await page.get_attribute("#journal-export", "href")
        assert href.startswith("/api/alarms/journal.csv?") and "user=operator" in href
        async with page.expect_download() as download_info:
            await page.click("#journal-export")
        download = await download_info.value
        assert download.suggested_filename.startswith("alarm-journal-") and download.suggested_filename.endswith(".csv")
        text = Path(await download.path()).read_text()
        assert text.splitlines()[0].startswith("time_utc,time,plant,alarm,transition")
        assert ",t01_input_full,acknowledged," in text and ",operator,hmi:operator@127.0.0.1," in text
        assert not errors, errors
    await context.close()
    await back_to_normal(plant)


async def test_a_viewer_has_no_buttons_and_a_forged_request_is_refused(browser: Any, plant: Plant) -> None:
    await raise_alarm(plant, "t01")
    forge = """async () => {
        const session = await (await fetch('/api/session')).json();
        const answer = await fetch('/api/commands/alarms.acknowledge', {method: 'POST', credentials: 'same-origin',
            headers: {'Content-Type': 'application/json', 'X-CSRF-Token': session.csrf || ''}, body: JSON.stringify({alarm: 't01_input_full'})});
        return [answer.status, await answer.json()];
    }"""
    context, page, errors = await open_page(browser, plant.url + "#/alarms")
    async with screenshot_on_failure(page, "alarm-viewer"):
        await ready(page)
        for who in ("visitor", "viewer"):
            if who == "viewer":
                await log_in(page, "viewer")
                await page.goto(plant.url + "#/alarms")
                await ready(page)
            await page.wait_for_selector("tr[data-alarm='t01_input_full'][data-state='unacknowledged']")
            assert await page.locator("[data-action]").count() == 0, who
            status, body = await page.evaluate(forge)
            assert status == 403, (who, body)
            assert body["error"] == ("log in to acknowledge alarms" if who == "visitor" else "role viewer may not acknowledge alarms")
        assert state(plant, "t01_input_full") == "unacknowledged"
        assert not [error for error in errors if "403" not in error], errors  # the forged fetch's 403 is logged by the browser
    await context.close()
    await back_to_normal(plant)


async def test_a_shelved_alarm_with_a_reason_expires_by_itself(browser: Any, plant: Plant) -> None:
    await raise_alarm(plant, "t02")
    context, page, errors = await open_page(browser, plant.url + "#/alarms")
    async with screenshot_on_failure(page, "alarm-shelve"):
        await ready(page)
        await log_in(page, "operator")
        await page.click("tr[data-alarm='t02_input_full'] [data-action='shelve']")
        dialog = page.locator("dialog.action-dialog")
        await dialog.locator("button[type=submit]").click()  # no reason: refused before it is sent
        assert await dialog.locator(".refusal").text_content() == "Give a reason: shelving is recorded with it."
        await page.fill("#shelve-reason", "sensor maintenance")
        await page.select_option("#shelve-duration", "custom")
        await page.fill("#shelve-custom", "30s")
        # Read before asking: read after the reply, it lagged the shelve by the round trip (up
        # to 0.5 simulated s at 10x), as much as the expiry may lag on its way to the page.
        asked_at = plant.runtime.clock.now()
        await dialog.locator("button[type=submit]").click()
        await dialog.locator(".done").wait_for()
        # Not annunciated while shelved; the banner counts it; the shelved view says by whom, why and until when.
        await page.wait_for_selector("tr[data-alarm='t02_input_full']", state="detached")
        await page.wait_for_function("() => document.querySelector(\"#alarm-banner [data-count='shelved'] b\")?.textContent === '1'")
        await page.select_option("#alarm-view", "shelved")
        row = page.locator("tr[data-alarm='t02_input_full'][data-state='shelved']")
        await row.wait_for()
        assert (await row.locator(".astate-text").text_content()).startswith("Shelved (until ")
        assert await row.locator(".comment").text_content() == "shelved by operator: sensor maintenance"
        assert await row.locator("[data-action='unshelve']").count() == 1
        # 30 simulated seconds later (3 s real) it is back, unacknowledged, without anyone doing anything.
        await page.select_option("#alarm-view", "annunciated")
        await page.wait_for_selector("tr[data-alarm='t02_input_full'][data-state='unacknowledged']", timeout=15000)
        assert plant.runtime.clock.now() - asked_at >= 30.0
        rows = await plant.runtime.commands.call("alarms.journal", {"alarm": "t02_input_full", "transition": ["shelved", "shelving_expired"]}, "test")
        expired, shelved = rows[0], rows[1]
        assert (shelved["transition"], shelved["user"], shelved["comment"]) == ("shelved", "operator", "sensor maintenance")
        assert expired["transition"] == "shelving_expired" and expired["state"] == "unacknowledged"
        assert expired["time"] - shelved["time"] == pytest.approx(30.0, abs=0.2)  # on the runtime clock
        assert not errors, errors
    await context.close()
    await back_to_normal(plant)


async def test_the_trend_page_draws_recorded_history_and_follows_the_live_tail(browser: Any, plant: Plant) -> None:
    for value in (11.0, 22.0, 33.0):
        plant.drive(limit=value)
        await asyncio.sleep(0.2)  # 2 simulated seconds apart
    # Recorded and committed (flush period 0.2 s) before the page asks.
    await wait_until(lambda: 33.0 in [s.value for s in plant.adapters["history"]._reader.raw("limit", 0, 2e9).samples], message="history written")
    context, page, errors = await open_page(browser, plant.url + "#/trends?tags=limit,t01_iBL&range=10m")
    async with screenshot_on_failure(page, "trend-page"):
        await ready(page)
        values = "(pen) => document.querySelector('#trend-chart').trendChart.samples[pen].map(([, v]) => v).filter((v) => v !== null)"
        drawn = await page.evaluate(f"({values})(0)")
        assert [11.0, 22.0, 33.0] == [value for value in drawn if value in (11.0, 22.0, 33.0)]  # from the historian, in order
        assert await page.evaluate("() => document.querySelector('#trend-chart').trendChart.pens.map((p) => p.unit)") == ["bar", "%"]
        assert await page.locator("#trend-chart .uplot").count() == 1
        axes = await page.evaluate("() => document.querySelector('#trend-chart').trendChart.plot.axes.map((a) => [a.scale, a.label ?? null])")
        assert axes == [["x", None], ["bar", "bar"], ["%", "%"]]  # one axis per unit (drawn on the canvas)
        assert await page.text_content("#trend-live") == "live"
        end_before = float(await page.get_attribute("#trend-chart", "data-end") or 0) if await page.get_attribute("#trend-chart", "data-end") else 0.0
        # The live tail: a new value arrives over the live channel, not from a new query.
        plant.drive(limit=44.0)
        await page.wait_for_function(f"() => ({values})(0).at(-1) === 44")
        await page.wait_for_function(f"() => Number(document.querySelector('#trend-chart').dataset.end) > {end_before}")
        x_max = await page.evaluate("() => document.querySelector('#trend-chart').trendChart.plot.scales.x.max")
        assert abs(x_max - plant.runtime.clock.wall()) < 3 * SPEED  # the window ends now, on the runtime clock
        # Zoom in: the range no longer ends now, so the tail stops and the page says so.
        await page.click("button[aria-label='Zoom in']")
        await page.wait_for_selector("#trend-live >> text=paused")
        span = await page.evaluate("() => { const x = document.querySelector('#trend-chart').trendChart.plot.scales.x; return x.max - x.min; }")
        assert span == pytest.approx(300.0, rel=0.01)
        await page.click("text=Back to live")
        await page.wait_for_selector("#trend-live >> text=live")
        assert not errors, errors
    await context.close()


async def test_a_tags_details_show_a_small_trend_of_its_last_hour(browser: Any, plant: Plant) -> None:
    plant.drive(limit=5.0)
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=limit")
    async with screenshot_on_failure(page, "tag-details"):
        await ready(page)
        await page.click(".vrow[data-tag='limit'] .name")
        dialog = page.locator("dialog.tag-details[data-tag='limit']")
        await dialog.wait_for()
        await page.wait_for_function("() => Number(document.querySelector('#mini-trend')?.dataset.points) >= 2")
        assert await dialog.locator("a[href='#/trends?tags=limit&range=1h']").count() == 1
        assert await dialog.locator(".live-value").text_content() == "5 bar"
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=str(ARTIFACTS / "supervisory-tag-details-desktop.png"))
        # A tag without history has no trend.
        await page.keyboard.press("Escape")
        await page.fill("input[type=search]", "iBC")
        await page.click(".vrow[data-tag='t01_iBC'] .name")
        await page.locator("dialog.tag-details[data-tag='t01_iBC']").wait_for()
        await asyncio.sleep(0.3)
        assert await page.locator("#mini-trend").count() == 0
        assert not errors, errors
    await context.close()


async def test_the_alarm_sound_is_off_by_default_remembered_and_beeps_on_a_new_alarm(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "alarm-sound"):
        await ready(page)
        sound = page.locator("#alarm-banner .ab-sound")
        assert await sound.get_attribute("aria-pressed") == "false"
        await sound.click()
        assert await sound.get_attribute("aria-pressed") == "true"
        await page.reload()
        await ready(page)
        assert await page.get_attribute("#alarm-banner .ab-sound", "aria-pressed") == "true"  # remembered by this browser
        await page.click("#alarm-banner .ab-sound")  # a click on the page (browsers play sound only after one) ...
        await page.click("#alarm-banner .ab-sound")  # ... and sound on again
        tones = await page.get_attribute("#alarm-banner", "data-tones") or "0"
        await raise_alarm(plant, "t01")
        await page.wait_for_function(f"() => Number(document.querySelector('#alarm-banner').dataset.tones || 0) > {tones}")
        assert not errors, errors
    await context.close()
    await back_to_normal(plant)


PAGES = ("alarms", "alarms?show=shelved", "journal", "trends?tags=limit,t01_iBL,flag&range=10m")


async def test_every_supervisory_page_at_desktop_and_phone_width(browser: Any, plant: Plant) -> None:
    """No script error or CSP violation, nothing wider than a phone; screenshots for people to look at."""
    await raise_alarm(plant, "t01")
    await raise_alarm(plant, "t02", 100)
    plant.drive(flag=True)
    await plant.runtime.commands.call("alarms.acknowledge", {"alarm": "t01_input_full", "comment": "robot r02 on its way"}, "test")
    await plant.runtime.commands.call("alarms.shelve", {"alarm": "flag_on", "reason": "switch under test", "duration": "1h"}, "test")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    for label, width, height in (("desktop", 1280, 800), ("phone", 390, 844)):
        context, page, errors = await open_page(browser, plant.url + "#/overview", width=width, height=height)
        await ready(page)
        await log_in(page, "operator")
        for name in PAGES:
            picture = "supervisory-" + name.split("&")[0].replace("?", "-").replace("=", "-").replace(",", "-")
            async with screenshot_on_failure(page, f"{picture}-{label}-failed"):
                await page.goto(f"{plant.url}#/{name}")
                await ready(page)
                await asyncio.sleep(0.5)  # let values and the chart settle for the picture
                await page.screenshot(path=str(ARTIFACTS / f"{picture}-{label}.png"), full_page=True)
                overflow = await page.evaluate("() => document.documentElement.scrollWidth - window.innerWidth")
                assert overflow <= 1, f"{name} is {overflow} px wider than a {width} px screen"
        await page.goto(f"{plant.url}#/alarms")
        await ready(page)
        await page.click("tr[data-alarm='t02_input_full'] [data-action='shelve']")
        await page.screenshot(path=str(ARTIFACTS / f"supervisory-shelve-dialog-{label}.png"))
        assert not errors, errors
        await context.close()
    await back_to_normal(plant)


async def test_the_trend_page_says_clearly_when_the_chart_library_is_missing(browser: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                             caplog: pytest.LogCaptureFixture) -> None:
    front_end = tmp_path / "hmi"
    shutil.copytree(REPO / "hmi", front_end, ignore=shutil.ignore_patterns("node_modules"))  # as built without npm ci
    monkeypatch.setenv("SOFTPLC_HMI_DIR", str(front_end))
    with caplog.at_level(logging.WARNING, logger="softplc.adapters.hmi"):
        plain = await start_supervisory_plant(tmp_path / "plant", modbus=False)
    try:
        assert any("the trend library uPlot is missing" in record.getMessage() for record in caplog.records)
        context, page, errors = await open_page(browser, plain.url + "#/trends?tags=limit")
        async with screenshot_on_failure(page, "trend-missing-library"):
            await ready(page)
            message = await page.text_content("#trend-missing")
            assert message.startswith("The trend library (uPlot) is not installed in this HMI")
            assert "scripts/bootstrap.sh" in message
        await context.close()
    finally:
        await plain.stop()
