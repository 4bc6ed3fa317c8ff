"""The default plant loads and runs on the simulated clock."""

from softplc.clock import SimClock
from softplc.config import load_config
from softplc.runtime import Runtime

from conftest import REPO


async def test_default_plant_fills_buffers_on_sim_clock(tmp_path):
    config = load_config(REPO / "tagdb.yaml")
    runtime = Runtime(config, SimClock(), state_dir=tmp_path)
    reason = await runtime.run(duration=60.0)
    assert "duration" in reason
    # 30 items/min for 60 s: 30 items (the last may land exactly at the boundary)
    assert runtime.db.value("t01_iBM") in (29, 30)
    assert runtime.db.value("t01_iBL") == runtime.db.value("t01_iBM") * 1.0
