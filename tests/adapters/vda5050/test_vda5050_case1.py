"""Case I with a mixed fleet: two simulated TurtleBots and two vda-5050-lib vehicles serve the plant of
examples/vda5050 — same tags, same motion sequencers, same dispatcher — and a vehicle killed mid-trip
hands its task back while the others go on delivering."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO
from vda5050_support import ROADMAP, LibVehicles, start_plant, wait_for

from softplc.core.tags import Quality

EXAMPLE = REPO / "examples" / "vda5050"


@pytest.fixture(autouse=True)
def vda_5050_lib() -> None:
    LibVehicles.require()


def plant(directory: Path, url: str) -> Path:
    """The example's plant with its two VDA 5050 robots as vda-5050-lib vehicles on a test broker."""
    robots = (EXAMPLE / "robots.yaml").read_text()
    robots = robots.replace("vda5050: {manufacturer: softplc, serial_number: tb3}",
                            "vda5050: {manufacturer: acme, serial_number: v3, instant_actions_key: instantActions}")
    robots = robots.replace("vda5050: {manufacturer: softplc, serial_number: tb4}",
                            "vda5050: {manufacturer: acme, serial_number: v4, instant_actions_key: instantActions}")
    (directory / "robots.yaml").write_text(robots)
    text = (EXAMPLE / "tagdb.yaml").read_text()
    text = text.replace("../../robots/tasks.yaml", str(REPO / "robots" / "tasks.yaml"))
    text = text.replace("../../robots/maps/factory.yaml", str(REPO / "robots" / "maps" / "factory.yaml"))
    text = text.replace("../../robots/roadmap.yaml", str(ROADMAP))
    text = text.replace("  url: mqtt://127.0.0.1:1884\n  embedded: true\n", f"  url: {url}\n  keepalive: 2s\n")
    assert url in text
    path = directory / "tagdb.yaml"
    path.write_text(text)
    return path


def situation(db) -> list[tuple[str, ...]]:
    """Each vehicle's navigation state and reason, its base, horizon and what traffic holds it for."""
    return [(robot, db.value(f"{robot}_navstate"), db.value(f"{robot}_navreason"), *(db.value(f"_sys.vda5050.{robot}.{name}")
             for name in ("base", "horizon", "waiting"))) for robot in ("r03", "r04")]


@pytest.mark.slow
async def test_case_one_with_simulated_robots_and_vda_5050_vehicles(tmp_path: Path, mosquitto) -> None:
    runtime = await start_plant(plant(tmp_path, mosquitto.url))
    db = runtime.db
    seen: dict[str, list[int]] = {"r03": [], "r04": []}

    def watch(tags) -> None:
        for tag in tags:
            robot = tag.name[:3]
            if tag.name.endswith("_currloc") and robot in seen and (not seen[robot] or seen[robot][-1] != tag.value):
                seen[robot].append(tag.value)
    undo = db.on_change(watch)
    options = {"speed": 1.0, "timeLapse": 4}
    try:
        async with LibVehicles(mosquitto.port, [{"manufacturer": "acme", "serialNumber": "v3", "x": 10.0, "y": 7.6, "lastNodeId": "q1"}],
                               **options), \
                LibVehicles(mosquitto.port, [{"manufacturer": "acme", "serialNumber": "v4", "x": 10.0, "y": 1.2, "lastNodeId": "q3"}],
                            **options) as fourth:
            delivered = lambda robot: any(seen[robot][i:i + 2] == [4, 0] for i in range(len(seen[robot])))  # noqa: E731
            try:
                await wait_for(lambda: delivered("r03") and delivered("r04"), 120, "both VDA 5050 vehicles delivered a load")
            except AssertionError as error:
                raise AssertionError(f"{error}; motion states seen {seen}; now {situation(db)}") from None
            assert all(db.value(f"{robot}_navstate") != "failed" for robot in ("r03", "r04"))
            stored = db.value("t01_qSM") + db.value("t02_qSM")
            assert stored > 0
            # r04 dies on its next trip: its task goes back, it takes no new one while it is away, the others carry on.
            await wait_for(lambda: db.value("r04_currloc") in (1, 3) and db.value("r04_navstate") == "moving", 60, "r04 on a trip")
            fourth.kill()
            await wait_for(lambda: not db.value("r04_online"), 5, "r04 lost")
            assert (db.value("r04_currloc"), db.value("r04_tcurr")) == (0, 0) and db["r04_xpos"].quality is Quality.BAD
            await wait_for(lambda: db.value("t01_qSM") + db.value("t02_qSM") > stored + 1, 90, "the rest of the fleet delivering on")
            assert db.value("r04_currloc") == 0 and db.value("r04_navstate") == "offline"
    finally:
        undo()
        await runtime.stop()
