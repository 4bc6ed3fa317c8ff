"""node-opcua (npm, a client none of us wrote) as an alarm display: events on the Server object,
ConditionRefresh for what was active before it connected, and Acknowledge.

Needs `node` and tests/node/node_modules (scripts/install-test-tools.sh runs `npm install` there).
"""

from __future__ import annotations

import asyncio
import json

from tests.adapters.opcua.test_opcua_node import NODE_DIR, _require_node_opcua
from tests.alarms_support import DRIVER, plant, running_alarm_plant
from tests.opcua_support import PASSWORDS

ALARMS = """
definitions:
  - {name: level_hi, limit: {tag: level, hi: 90}, priority: high, message: "level {value:.0f} m"}
  - {name: nav_failed, discrete: {tag: navstate, value: failed}, priority: critical}
"""


async def test_node_opcua_sees_active_conditions_after_refresh_live_transitions_and_acknowledges(tmp_path) -> None:
    node = _require_node_opcua()
    async with running_alarm_plant(tmp_path, plant(ALARMS)) as (runtime, server):
        runtime.db.submit([("level", 95.0)], DRIVER)  # active before the client connects
        for _ in range(300):
            if runtime.db.value("_sys.alarms.active") == 1:
                break
            await asyncio.sleep(0.01)
        process = await asyncio.create_subprocess_exec(
            node, "alarms_check.js", server.endpoint, "operator", PASSWORDS["operator"],
            cwd=NODE_DIR, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )
        assert process.stdout is not None and process.stderr is not None
        lines: list[str] = []
        try:
            while True:  # node-opcua may log on stdout too: read until the script says it refreshed
                line = (await asyncio.wait_for(process.stdout.readline(), 60)).decode()
                assert line, "node script ended early: " + "".join(lines)[-2000:] + (await process.stderr.read()).decode()[-2000:]
                lines.append(line)
                if line.startswith("REFRESHED"):
                    break
            runtime.db.submit([("navstate", "failed")], DRIVER)  # a live transition
            rest, errors = await asyncio.wait_for(process.communicate(), 60)
        finally:
            if process.returncode is None:
                process.kill()
        output = "".join(lines) + rest.decode()
        results = [line[len("RESULT "):] for line in output.splitlines() if line.startswith("RESULT ")]
        assert process.returncode == 0 and results, output[-2000:] + errors.decode()[-2000:]
        seen = json.loads(results[0])
        assert seen["beforeRefresh"] == 0 and seen["refreshStatus"].startswith("Good")
        refreshed = [event for event in seen["refreshed"] if event["ConditionName"] == "level_hi"]
        assert len(refreshed) == 1
        first = refreshed[0]
        assert (first["ActiveState.Id"], first["AckedState.Id"], first["Retain"], first["Severity"]) == (True, False, True, 700)
        assert first["Message"] == "level 95 m" and first["SourceName"] == "level"
        assert first["ConditionId"] == f"ns={server.namespace_index};s=alarms.level_hi"
        live = seen["live"]
        assert (live["ActiveState.Id"], live["Severity"], live["SourceName"]) == (True, 900, "navstate")
        assert seen["acknowledgeStatus"] == "Good"
        assert seen["acknowledged"]["AckedState.Id"] is True and seen["acknowledged"]["ActiveState.Id"] is True
        rows = await runtime.commands.call("alarms.journal", {"transition": "acknowledged"}, DRIVER)
        assert [(row["alarm"], row["user"], row["comment"]) for row in rows] == [("level_hi", "operator", "seen from node-opcua")]
