"""Trends drawn as the values were, in real headless Chromium: held to now, stepped where they step, gaps where nothing was recorded.

The drawing is judged from the chart's canvas (the pen's colour at a time and a value, through
uPlot's own scales), the labels from what uPlot laid out, measured with the axis's font.
"""

from __future__ import annotations

import asyncio
import math
import re
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from hmi_supervisory_support import PLANT, start_supervisory_plant
from hmi_support import (  # noqa: F401 (browser: a fixture)
    Plant,
    browser,
    open_page,
    ready,
    require_browser,
    screenshot_on_failure,
    wait_until,
)

from softplc.core.clock import SimClock
from softplc.core.tags import Quality

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")
SPEED = 10.0  # simulated seconds per real second

# The chart's canvas at (time, value) of pen `pen` (uPlot's scales): is the pen's colour painted within `reach` pixels?
PAINTED = """([pen, time, value, reach]) => {
  const chart = document.querySelector('#trend-chart').trendChart;
  const u = chart.plot;
  const series = u.series[pen + 1];
  const ratio = u.ctx.canvas.width / u.ctx.canvas.getBoundingClientRect().width;
  const x = Math.round(u.valToPos(time, 'x', true)), y = Math.round(u.valToPos(value, series.scale, true));
  const r = Math.round(reach * ratio);
  const pixels = u.ctx.getImageData(x - r, y - r, 2 * r + 1, 2 * r + 1).data;
  const want = chart.pens[pen].color.match(/\\w\\w/g).map((hex) => parseInt(hex, 16));
  for (let i = 0; i < pixels.length; i += 4) {
    if (Math.abs(pixels[i] - want[0]) + Math.abs(pixels[i + 1] - want[1]) + Math.abs(pixels[i + 2] - want[2]) < 60 && pixels[i + 3] > 200) return true;
  }
  return false;
}"""


RECORDED = '    - tags: ["t*_iBL", "t*_iBM", limit, flag, speed]\n'
assert RECORDED in PLANT
# `speed` recorded with swinging-door compression: its archive is a straight-line approximation.
COMPRESSED = PLANT.replace(RECORDED, '    - tags: ["t*_iBL", "t*_iBM", limit, flag]\n    - {tags: speed, compression: {deviation: 0.05}}\n')


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_supervisory_plant(tmp_path_factory.mktemp("hmi-trends"), clock=SimClock(speed=SPEED), modbus=False, text=COMPRESSED)
    yield plant
    await plant.stop()


def recorded(plant: Plant, tag: str, value: Any) -> bool:
    return value in [sample.value for sample in plant.adapters["history"]._reader.raw(tag, 0, 2e10).samples]


async def chart_ready(page: Any) -> None:
    await ready(page)
    await page.wait_for_function("() => document.querySelector('#trend-chart')?.trendChart?.plot")
    await page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")


async def test_a_constant_value_is_held_to_now_and_a_setpoint_steps(browser: Any, plant: Plant) -> None:
    clock = plant.runtime.clock
    plant.drive(limit=29.0, t01_iBM=10)
    await wait_until(lambda: recorded(plant, "limit", 29.0), message="29 recorded")
    first = clock.wall()
    await asyncio.sleep(40 / SPEED)
    plant.drive(limit=30.0, t01_iBM=20)
    await wait_until(lambda: recorded(plant, "limit", 30.0), message="30 recorded")
    second = clock.wall()
    await asyncio.sleep(40 / SPEED)  # then nothing changes: both values must be held to now
    # One pen a page: the two axes' scales could draw both lines on the same pixels.
    for tag, (low, middle_value, high) in (("limit", (29.0, 29.5, 30.0)), ("t01_iBM", (10, 15, 20))):
        context, page, errors = await open_page(browser, plant.url + f"#/trends?tags={tag}&range=10m")
        async with screenshot_on_failure(page, f"trend-held-and-stepped-{tag}"):
            await chart_ready(page)
            now = clock.wall()
            middle = (first + second) / 2
            # A setpoint (a float recorded on every change) and an integer hold their value until the next: a step, not a ramp.
            assert await page.evaluate(PAINTED, [0, middle, low, 1]), f"{tag}: {low} is not held until the next value"
            assert not await page.evaluate(PAINTED, [0, middle, middle_value, 2]), f"{tag} is drawn as a ramp"
            # The last value is held to now, not a dot at its last sample.
            assert await page.evaluate(PAINTED, [0, (second + now) / 2, high, 1]), f"{tag} is not held after its last sample"
            assert await page.evaluate(PAINTED, [0, now - 3 * SPEED, high, 1]), f"{tag} does not reach now"
            assert not errors, errors
        await context.close()


async def test_a_compressed_value_is_drawn_sloped(browser: Any, plant: Plant) -> None:
    clock = plant.runtime.clock
    begin = math.floor(clock.now()) + 1.05
    for step, value in enumerate([*range(0, 11), 9, 8]):  # up a ramp, a simulated second a step, then down: the turn closes the door at 10
        await clock.sleep_until(begin + step)
        plant.drive(speed=float(value))
    await wait_until(lambda: recorded(plant, "speed", 10.0), message="the ramp's top archived")
    archived = {sample.value: sample.time for sample in plant.adapters["history"]._reader.raw("speed", 0, 2e10).samples}
    assert 5.0 not in archived, archived  # the middle of the ramp is not stored: the drawing must slope through it
    middle = (archived[1.0] + archived[10.0]) / 2  # 0 is the starting value, stored when the run began
    context, page, errors = await open_page(browser, plant.url + "#/trends?tags=speed&range=10m")
    async with screenshot_on_failure(page, "trend-compressed-sloped"):
        await chart_ready(page)
        assert await page.evaluate(PAINTED, [0, middle, 5.5, 2]), "the ramp is not drawn as a slope"
        assert not await page.evaluate(PAINTED, [0, middle, 1.0, 2])
        assert not errors, errors
    await context.close()


async def test_the_first_pen_is_the_plants_levels_and_times_are_24_hour_and_apart(browser: Any, plant: Plant) -> None:
    context = await browser.new_context(viewport={"width": 1280, "height": 800}, timezone_id="America/New_York")
    page = await context.new_page()
    async with screenshot_on_failure(page, "trend-default-and-clock"):
        await page.goto(plant.url + "#/trends")  # no pens asked for, none remembered by this browser
        await chart_ready(page)
        assert await page.evaluate("() => document.querySelector('#trend-chart').trendChart.pens.map((pen) => pen.tag)") == ["t01_iBL", "t02_iBL"]
        for span in ("10m", "1h", "8h", "1d", "7d"):
            await page.click(f"button[data-range='{span}']")
            await page.wait_for_function(f"() => location.hash.includes('range={span}')")
            await page.evaluate("() => new Promise((done) => setTimeout(() => requestAnimationFrame(done), 400))")
            labels = await page.evaluate("""() => {
              const u = document.querySelector('#trend-chart').trendChart.plot;
              const axis = u.axes[0];
              const measure = document.createElement('canvas').getContext('2d');
              measure.font = axis.font[0];
              return axis._values.map((text, i) => ({ text: String(text), at: u.valToPos(axis._splits[i], 'x'),
                widths: String(text).split('\\n').map((line) => measure.measureText(line).width) }));
            }""")
            assert labels, f"{span}: no time labels"
            for label in labels:
                assert "am" not in label["text"].lower() and "pm" not in label["text"].lower(), f"{span}: 12-hour clock in {label['text']!r}"
                first_line = label["text"].split("\n")[0]
                assert first_line[:2].isdigit(), f"{span}: {first_line!r}"
            for line in (0, 1):
                spans = [(label["at"] - label["widths"][line] / 2, label["at"] + label["widths"][line] / 2)
                         for label in labels if len(label["widths"]) > line]
                for (_, right), (left, _) in zip(spans, spans[1:]):
                    assert right + 4 <= left, f"{span}: time labels overlap: {[label['text'] for label in labels]}"
        legend = await page.evaluate("() => { const u = document.querySelector('#trend-chart').trendChart.plot; return u.series[0].value(u, u.scales.x.min); }")
        assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d", legend), legend  # 24-hour, no am/pm
    await context.close()


async def test_a_runtime_restart_is_a_gap_not_a_ramp(browser: Any, tmp_path: Path) -> None:
    # Real time: a simulated run starts a new history each time, a real one goes on with the same.
    folder = tmp_path / "plant"
    first = await start_supervisory_plant(folder, modbus=False)
    first.drive(limit=29.0)
    await wait_until(lambda: recorded(first, "limit", 29.0), message="29 recorded")
    await asyncio.sleep(0.5)
    stopping = time.time()
    await first.stop()
    stopped = time.time()
    await asyncio.sleep(2.0)  # the outage
    second = await start_supervisory_plant(folder, modbus=False)
    try:
        second.drive(limit=30.0)
        await wait_until(lambda: recorded(second, "limit", 30.0), message="30 recorded")
        samples = second.adapters["history"]._reader.raw("limit", 0, 2e10).samples
        ends = [sample for sample in samples if sample.quality is Quality.BAD]
        # "No data from here", stamped while the runtime stopped (a stop under load takes a while;
        # the runtime's wall clock is its start's wall time plus the monotonic clock: 50 ms leeway).
        assert len(ends) == 1 and math.isnan(ends[0].value), samples
        assert stopping - 0.05 <= ends[0].time <= stopped + 0.05, (stopping, ends[0].time, stopped)
        restarted = min(sample.time for sample in samples if sample.time > ends[0].time)
        start, end = math.floor(ends[0].time - 2), math.ceil(restarted + 2)
        context, page, errors = await open_page(browser, second.url + f"#/trends?tags=limit&range=custom&from={start}&to={end}")
        async with screenshot_on_failure(page, "trend-restart-gap"):
            await chart_ready(page)
            # 29 up to the stop, nothing in the outage, 30 (the restart's 0, then the write) after it.
            assert await page.evaluate(PAINTED, [0, ends[0].time - 0.3, 29.0, 1])
            outage = (ends[0].time + restarted) / 2
            values = await page.evaluate("() => { const u = document.querySelector('#trend-chart').trendChart.plot; const scale = u.scales[u.series[1].scale]; return [scale.min, scale.max]; }")
            for step in range(11):
                value = values[0] + (values[1] - values[0]) * step / 10
                assert not await page.evaluate(PAINTED, [0, outage, value, 2]), f"a line across the outage at {value}"
            written = next(sample.time for sample in samples if sample.value == 30.0)
            assert await page.evaluate(PAINTED, [0, written + 0.2, 30.0, 1])
            assert not errors, errors
        await context.close()
    finally:
        await second.stop()
