"""The overview's factory map and cards in real headless Chromium: labels that never overlap, teams that say they are full.

Overlaps are judged on the boxes Chromium lays out (getBoundingClientRect of every label, bar
and goal mark of the map), and "hidden" by what Chromium finds on top at a label's centre
(elementFromPoint): what a user sees, not what the code meant.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest
import pytest_asyncio
from hmi_support import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
    DRIVER,
    Plant,
    browser,
    log_in,
    open_page,
    plant_yaml,
    ready,
    require_browser,
    screenshot_on_failure,
    start_plant,
)

from softplc.core.tags import Quality

require_browser()

pytestmark = pytest.mark.asyncio(loop_scope="module")


def overview_plant() -> str:
    """The HMI test plant with what the map and the cards draw besides: robots' goals, tasks' weights."""
    text = plant_yaml()
    robot_tags = "      currloc:  {type: uint16, max: 4}\n"
    task_tags = '      qSL: {type: float32, unit: "%", min: 0, max: 100, access: ro}\n'
    assert robot_tags in text and task_tags in text
    text = text.replace(robot_tags, robot_tags + "      xgoal:    {type: float64, unit: m}\n      ygoal:    {type: float64, unit: m}\n")
    return text.replace(task_tags, task_tags + "      Tw: {type: float64, access: ro}\n")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Plant]:
    plant = await start_plant(tmp_path_factory.mktemp("hmi-overview"), text=overview_plant())
    yield plant
    await plant.stop()


# Every label, bar and goal mark on the map (shown ones), with what it is, its box, and whether it is on top at its centre.
MAP_LABELS = """() => {
  const floor = document.querySelector('.floor');
  const shown = (node) => node.getAttribute('visibility') !== 'hidden' && !node.closest('[visibility="hidden"]') && node.getBoundingClientRect().width > 0;
  const items = [];
  const add = (node, what) => {
    if (!shown(node)) return;
    const box = node.getBoundingClientRect();
    const top = document.elementFromPoint(box.x + box.width / 2, box.y + box.height / 2);
    items.push({ what, box: [box.left, box.top, box.right, box.bottom], onTop: Boolean(top && (node === top || node.contains(top))), text: node.textContent });
  };
  for (const station of floor.querySelectorAll('.station')) {
    const name = `${station.dataset.task} ${station.dataset.kind}`;
    for (const text of station.querySelectorAll('text')) add(text, `${name} text "${text.textContent}"`);
    for (const bar of station.querySelectorAll('.bar-track')) add(bar, `${name} bar`);
  }
  for (const label of floor.querySelectorAll('.robot-tag')) {
    for (const part of label.querySelectorAll('text')) add(part, `robot ${label.dataset.robot} label "${part.textContent}"`);
  }
  for (const goal of floor.querySelectorAll('.goal')) add(goal, `goal of ${goal.dataset.robot}`);
  const area = floor.getBoundingClientRect();
  return { items, area: [area.left, area.top, area.right, area.bottom] };
}"""


def overlaps(items: list[dict[str, Any]]) -> list[str]:
    found = []
    for i, first in enumerate(items):
        for second in items[i + 1:]:
            a, b = first["box"], second["box"]
            if min(a[2], b[2]) - max(a[0], b[0]) > 0.5 and min(a[3], b[3]) - max(a[1], b[1]) > 0.5:
                found.append(f"{first['what']} overlaps {second['what']}")
    return found


async def settle(page: Any, robots: dict[str, tuple[float, float]]) -> None:
    for robot, (x, y) in robots.items():
        await page.wait_for_function(
            "([robot, x, y]) => { const m = document.querySelector(`.floor .robot[data-robot='${robot}']`);"
            " return m && Math.abs(m.dataset.x - x) < 0.01 && Math.abs(m.dataset.y - y) < 0.01; }", arg=[robot, x, y])
    await page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")


SCENES = {
    # r01 parked a little beside Task One's source, loading; r02 on its way to Task Two's destination.
    "parked at T1 IN": dict(r01_xpos=3.8, r01_ypos=7.3, r01_navstate="arrived", r01_status=True, r01_tcurr=1, r01_currloc=2,
                            r01_xgoal=3.5, r01_ygoal=7.5, r02_xpos=19.4, r02_ypos=3.1, r02_navstate="moving", r02_status=True,
                            r02_tcurr=2, r02_currloc=3, r02_xgoal=20.1, r02_ygoal=2.4),
    # r02 parked at Task Two's destination (by the map's right edge), r01 about to reach Task One's destination.
    "parked at T2 OUT": dict(r02_xpos=19.9, r02_ypos=2.5, r02_navstate="arrived", r02_status=True, r02_tcurr=2, r02_currloc=4,
                             r02_xgoal=20.1, r02_ygoal=2.4, r01_xpos=2.3, r01_ypos=3.0, r01_navstate="moving", r01_status=True,
                             r01_tcurr=1, r01_currloc=3, r01_xgoal=1.8, r01_ygoal=2.5),
}


@pytest.mark.parametrize("scene", list(SCENES))
async def test_no_label_of_the_map_overlaps_another_or_hides_under_a_robot(browser: Any, plant: Plant, scene: str) -> None:
    plant.drive(t01_iBM=100, t02_iBM=7, t01_qSM=42, t02_qSM=100, **SCENES[scene])
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, f"map-labels-{scene.replace(' ', '-')}"):
        await ready(page)
        values = SCENES[scene]
        await settle(page, {robot: (values[f"{robot}_xpos"], values[f"{robot}_ypos"]) for robot in ("r01", "r02")})
        drawn = await page.evaluate(MAP_LABELS)
        items = drawn["items"]
        texts = [item["text"] for item in items]
        for expected in ("100/100", "100%", "42", "r01", "r02", "T1", "T2"):
            assert any(expected in text for text in texts), f"{expected} is not drawn: {texts}"
        assert any(item["what"].startswith("goal of") for item in items), "no goal is drawn"
        assert overlaps(items) == []
        assert [item["what"] for item in items if not item["onTop"] and "bar" not in item["what"] and "goal" not in item["what"]] == []
        left, top, right, bottom = drawn["area"]
        assert [item["what"] for item in items if item["box"][0] < left - 0.5 or item["box"][2] > right + 0.5
                or item["box"][1] < top - 0.5 or item["box"][3] > bottom + 0.5] == []  # nothing cut off at the map's edge
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        await page.locator(".floor").screenshot(path=str(ARTIFACTS / f"map-{scene.replace(' ', '-')}.png"))
        assert not errors, errors
    await context.close()


async def test_a_bottleneck_whose_team_is_full_says_so_and_why_the_next_robot_goes_elsewhere(browser: Any, plant: Plant) -> None:
    # Task One: the fullest input buffer and the lowest weight, but both robots are on it (2 of at most 2).
    plant.drive(t01_iBM=90, t02_iBM=20, t01_Tw=-2.0, t02_Tw=0.5, r01_tcurr=1, r01_currloc=1, r01_status=True,
                r02_tcurr=1, r02_currloc=3, r02_status=True)
    context, page, errors = await open_page(browser, plant.url + "#/overview")
    async with screenshot_on_failure(page, "team-full"):
        await ready(page)
        one, two = page.locator(".task-card[data-task='t01']"), page.locator(".task-card[data-task='t02']")
        await page.wait_for_function("() => document.querySelector('.task-card[data-task=\"t01\"] .badges')?.textContent.includes('team full 2/2')")
        assert await one.locator(".badge.bottleneck").count() == 1
        assert await one.locator(".badge.next").count() == 0  # its team has no room: the next robot cannot go there
        assert await two.locator(".badge.next").count() == 1
        note = await one.locator(".task-note").text_content()
        assert "team is full (2/2)" in note and "Task Two" in note
        assert "2/2" in await one.locator(".team").text_content()
        # One robot leaves Task One: its team has room again, and the lowest weight takes the next robot.
        plant.drive(r02_tcurr=0, r02_currloc=0, r02_status=False)
        await page.wait_for_function("() => document.querySelector('.task-card[data-task=\"t01\"] .badge.next') !== null")
        assert "team full" not in await one.locator(".badges").text_content()
        assert "1/2" in await one.locator(".team").text_content()
        assert not errors, errors
    await context.close()


async def test_on_a_phone_the_role_and_the_tags_quality_are_shown_whole(browser: Any, plant: Plant) -> None:
    context, page, errors = await open_page(browser, plant.url + "#/tags?q=limit", width=390, height=844)
    async with screenshot_on_failure(page, "phone-role-quality"):
        await ready(page)
        await log_in(page, "engineer")
        clipped = "(node) => node.scrollWidth > node.clientWidth + 1"
        assert not await page.locator("#user-box .who").evaluate(clipped), "the user and role are cut off"
        role = page.locator("#user-box .role")
        assert await role.text_content() == "engineer"
        box, who = await role.bounding_box(), await page.locator("#user-box .who").bounding_box()
        assert box and who and box["x"] + box["width"] <= min(who["x"] + who["width"], 390) + 0.5, "the role is cut off"
        assert not await role.evaluate(clipped)
        quality = page.locator(".vrow[data-tag='limit'] .qual")
        await quality.wait_for()
        assert await quality.is_visible() and await quality.text_content() == "good"
        assert not await page.locator(".vrow[data-tag='limit'] .qcol").evaluate(clipped)
        assert await page.locator(".vhead .qcol").is_visible()
        overflow = await page.evaluate("() => document.documentElement.scrollWidth - window.innerWidth")
        assert overflow <= 1
        # The longest quality word fits too.
        plant.db.submit_quality(["limit"], Quality.UNCERTAIN, DRIVER)
        await page.wait_for_function("() => document.querySelector(\".vrow[data-tag='limit'] .qual\")?.textContent === 'uncertain'")
        assert not await page.locator(".vrow[data-tag='limit'] .qcol").evaluate(clipped)
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=str(ARTIFACTS / "phone-tags-with-quality.png"))
        plant.db.submit_quality(["limit"], Quality.GOOD, DRIVER)
        assert not errors, errors
    await context.close()
