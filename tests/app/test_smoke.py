"""The default plant (tagdb.yaml) runs on the simulated clock and its robots deliver material."""

from conftest import REPO

from softplc.app.runtime import Runtime
from softplc.config import load_config
from softplc.core.clock import SimClock
from softplc.core.expression import Condition
from softplc.engine.scan import ProgramState


async def test_default_plant_delivers_until_an_output_storage_is_full(tmp_path):
    config = load_config(REPO / "tagdb.yaml")
    runtime = Runtime(config, SimClock(), state_dir=tmp_path)
    from softplc.app.adapters import build_adapters

    for adapter in build_adapters(config, None):
        if adapter.name == "fleet":  # the robots, without network servers
            runtime.add_adapter(adapter)
    full = Condition("t01_qSL >= 100 or t02_qSL >= 100", runtime.db.names())
    reason = await runtime.run(duration=1800.0, until=full)
    db = runtime.db
    assert reason.startswith("condition met"), reason
    assert db.value("t01_goals") > 0 and db.value("t02_goals") > 0
    assert db.value("t01_qSM") + db.value("t02_qSM") >= 100
    faulted = [i.name for t in runtime.tasks for i in t.programs if i.state is not ProgramState.RUNNING]
    assert faulted == []
