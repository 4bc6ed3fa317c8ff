"""The overview shows the roadmap, each VDA 5050 vehicle's order (base solid, horizon dashed), its connection and errors —
through the `vda5050.roadmap` query and the `_sys.vda5050.*` tags, in Debian's Chromium."""

from __future__ import annotations

import asyncio
import functools
from pathlib import Path

import pytest
from hmi_support import ARTIFACTS, browser, open_page, ready, require_browser, screenshot_on_failure  # noqa: F401 (fixture)
from vda5050_support import MAP, adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.clients.robot_agent.vda5050.agent import VehicleAgent
from softplc.core.clock import RealClock
from softplc.protocols.mqtt import MqttConnection
from softplc.protocols.mqtt_settings import MqttSettings
from softplc.robotics.controller import SpeedLimits
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import load_robots

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")


@functools.cache
def factory_floor() -> Floor:
    return Floor(load_map(MAP))


async def test_the_overview_draws_the_roadmap_the_orders_and_the_vehicles_state(tmp_path: Path, mosquitto, browser) -> None:
    tagdb = write_plant(tmp_path, mosquitto.url, [vehicle_yaml("r01", "tb1", 7.925, 5.925, speed=0.3),
                                                  vehicle_yaml("r02", "tb2", 7.925, 2.925, speed=0.3)])
    runtime = await start_plant(tagdb, hmi=True)
    db = runtime.db
    robots = load_robots(tagdb.parent / "robots.yaml")
    vehicle = VehicleAgent(robots["r01"], factory_floor(), MqttSettings(port=mosquitto.port, client_id="hmi"), clock=RealClock(),
                           state_interval=0.5, limits=SpeedLimits(0.3, 1.0))
    driving = asyncio.ensure_future(vehicle.run())
    liar = MqttConnection(MqttSettings(port=mosquitto.port, client_id="liar"), "r02", RealClock())
    lying = asyncio.ensure_future(liar.run())
    try:
        await wait_for(lambda: db.value("r01_online") and liar.connected, 10, "r01 reports")
        db.submit([("r01_xgoal", 18.5), ("r01_ygoal", 7.5), ("r01_status", True)], "test")
        await wait_for(lambda: db.value("_sys.vda5050.r01.horizon") != "", 10, "an order with a horizon")
        await liar.publish("uagv/v2/softplc/tb2/state", b"{ not json")  # r02's error shows on the overview
        await wait_for(lambda: db.value("_sys.vda5050.r02.error") != "", 10, "r02's error")
        url = adapter(runtime, "hmi").url
        for width, height in ((1280, 800), (390, 844)):
            context, page, errors = await open_page(browser, url, width=width, height=height)
            async with screenshot_on_failure(page, f"vda5050-overview-{width}"):
                await ready(page)
                await page.wait_for_selector(".vda-panel tr[data-robot='r01']")
                lanes = await page.locator("g.roadmap line").count()
                assert lanes == len({tuple(sorted(key.split("-"))) for key in adapter(runtime, "vda5050").roadmap.lanes})
                await page.wait_for_function("() => (document.querySelectorAll('g.vda-orders polyline')[1]?.getAttribute('points') || '').length > 0")
                base, horizon = [await line.get_attribute("stroke-dasharray") for line in await page.locator("g.vda-orders polyline").all()][1::-1]
                assert base is None and horizon == "8 6"  # the base solid, the horizon dashed
                r01 = await page.locator(".vda-panel tr[data-robot='r01']").inner_text()
                r02 = await page.locator(".vda-panel tr[data-robot='r02']").inner_text()
                assert "ONLINE" in r01 and "→" in r01
                assert "lost" in r02 and "not JSON" in r02
                ARTIFACTS.mkdir(parents=True, exist_ok=True)
                await page.screenshot(path=str(ARTIFACTS / f"vda5050-overview-{width}.png"), full_page=True)
                assert errors == []
            await context.close()
    finally:
        for task in (driving, lying):
            task.cancel()
        await asyncio.gather(driving, lying, return_exceptions=True)
        await liar.close()
        await runtime.stop()
