"""The HMI of a redundant pair's member shows the pair on every page and follows the active (Chromium, real servers)."""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path
from typing import Any

import pytest

from softplc.app.adapters import build_adapters
from softplc.app.runtime import Runtime
from softplc.config import load_config
from tests.adapters.redundancy.pair_support import free_port, write_pair
from tests.adapters.redundancy.test_pair_inprocess import role, until
from tests.hmi_support import ARTIFACTS, browser, open_page, require_browser, screenshot_on_failure  # noqa: F401

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")

SERVERS = """
servers:
  opcua: {enabled: false}
  modbus: {enabled: false}
"""


def member(path: Path, name: str, state: Path, hmi_port: int) -> Runtime:
    config = load_config(path)
    runtime = Runtime(config, state_dir=state / name)
    for adapter in build_adapters(config, argparse.Namespace(redundancy_member=name, hmi_port=hmi_port)):
        runtime.add_adapter(adapter)
    return runtime


async def test_a_standby_page_goes_to_the_active_and_an_active_page_to_its_successor(browser: Any, tmp_path: Path, etcd: Any) -> None:
    ports = {"a": free_port(), "b": free_port()}
    urls = {name: f"http://127.0.0.1:{port}/" for name, port in ports.items()}
    path = write_pair(tmp_path, etcd.endpoint, servers=SERVERS, interval="100ms",
                      ports={"hmi_a_url": urls["a"], "hmi_b_url": urls["b"]})  # type: ignore[dict-item]
    a, b = member(path, "a", tmp_path, ports["a"]), member(path, "b", tmp_path, ports["b"])
    await asyncio.gather(a.start(), b.start())
    try:
        await until(lambda: role(a) == "ACTIVE" and b.db.value("_sys.redundancy.peer_ok"), 15, "a active, b in sync")
        context, page, errors = await open_page(browser, urls["b"] + "#/tags")
        async with screenshot_on_failure(page, "pair-standby"):
            banner = page.locator(".pair-banner")
            try:
                await banner.wait_for()
            except Exception:
                raise AssertionError(f"no pair banner; the page's errors: {errors}") from None
            await page.locator(".pair-banner", has_text="STANDBY").wait_for()
            text = await banner.text_content()
            assert "this runtime (b) is STANDBY; the active is a" in text and "going to the active" in text
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            await page.screenshot(path=str(ARTIFACTS / "pair-standby-1280.png"))
            await page.wait_for_url(urls["a"] + "#/tags", timeout=10_000)  # followed the active, same page
            await page.locator(".pair-banner", has_text="(a) is ACTIVE").wait_for()
            await page.screenshot(path=str(ARTIFACTS / "pair-active-1280.png"))
            await page.set_viewport_size({"width": 390, "height": 844})
            await page.screenshot(path=str(ARTIFACTS / "pair-active-390.png"))
            await a.stop()  # the active goes away: b takes over, and the page follows it
            await page.wait_for_url(urls["b"] + "#/tags", timeout=20_000)
            await page.locator(".pair-banner", has_text="(b) is ACTIVE").wait_for(timeout=10_000)
            await page.screenshot(path=str(ARTIFACTS / "pair-after-failover-390.png"))
        assert not [error for error in errors if "pair" in error], errors
        await context.close()
    finally:
        for runtime in (a, b):
            await runtime.stop()
