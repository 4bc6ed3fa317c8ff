"""The historian's commands (`history.*`), as the HMI's trend page and the OPC UA door call them: plain data in
process, JSON through Objects/Commands, a clear refusal for each bad argument (issue 16)."""

from __future__ import annotations

import json

import pytest
import pytest_asyncio
from asyncua import ua

from softplc.core.commands import CommandRefused
from softplc.core.roles import Role
from softplc.core.tagdb import Origin
from tests.opcua_history_support import EPOCH, recorded_plant
from tests.opcua_support import client_for

pytestmark = pytest.mark.asyncio(loop_scope="module")

VIEWER = Origin("hmi", "viewer", role=Role.VIEWER)


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with recorded_plant(tmp_path_factory.mktemp("history-commands")) as (runtime, server):
        yield runtime, server


async def test_a_viewer_reads_history_as_plain_data(plant) -> None:
    runtime, _ = plant
    call = runtime.commands.call
    assert await call("history.tags", {}, VIEWER) == [
        {"tag": "level", "type": "float64", "unit": "m", "interpolation": "sloped", "compressed": False},
        {"tag": "note", "type": "string", "unit": "", "interpolation": "stepped", "compressed": False},
        {"tag": "pressure", "type": "float64", "unit": "bar", "interpolation": "sloped", "compressed": False},
        {"tag": "steps", "type": "int32", "unit": "", "interpolation": "stepped", "compressed": False}]
    assert "average" in await call("history.aggregates", {}, VIEWER)
    raw = await call("history.read_raw", {"tag": "pressure", "start": EPOCH + 15, "end": EPOCH + 45, "bounds": True}, VIEWER)
    assert raw == {"continuation": None, "samples": [
        {"time": EPOCH + 10, "value": 10.0, "quality": "good", "flags": []},
        {"time": EPOCH + 20, "value": 5.0, "quality": "bad", "flags": []},
        {"time": EPOCH + 30, "value": 30.0, "quality": "good", "flags": []},
        {"time": EPOCH + 40, "value": 20.0, "quality": "uncertain", "flags": []},
        {"time": EPOCH + 50, "value": 50.0, "quality": "good", "flags": []}]}
    pages, continuation = [], None
    while True:
        page = await call("history.read_processed", {"tag": "level", "start": EPOCH, "end": EPOCH + 40, "interval": 10,
                                                     "aggregate": "time_average", "limit": 3, "continuation": continuation}, VIEWER)
        pages.append([round(s["value"], 6) for s in page["samples"]])
        continuation = page["continuation"]
        if continuation is None:
            break
    assert pages == [[5.0, 15.0, 25.0], [35.0]]
    at = await call("history.read_at_time", {"tag": "steps", "times": [EPOCH + 4, EPOCH - 1]}, VIEWER)
    assert at["samples"] == [{"time": EPOCH + 4, "value": 1, "quality": "good", "flags": ["interpolated"]},
                             {"time": EPOCH - 1, "value": None, "quality": "bad", "flags": ["no_data"]}]
    plot = await call("history.plot", {"tag": "level", "start": EPOCH, "end": EPOCH + 40, "max_points": 10}, VIEWER)
    assert plot["decimated"] and len(plot["samples"]) <= 10 and plot["bucket"] == 8.0
    assert {s["value"] for s in plot["samples"]} >= {0.0, 39.0}  # the extremes are kept
    for result in (raw, page, at, plot):
        json.dumps(result, allow_nan=False)  # what the OPC UA door sends


@pytest.mark.parametrize(("command", "arguments", "refusal"), [
    ("history.read_raw", {}, "tag: a tag name is needed"),
    ("history.read_raw", {"tag": "spare"}, "no history of spare"),
    ("history.read_raw", {"tag": "level", "start": "yesterday"}, "start: Unix seconds (a number), not 'yesterday'"),
    ("history.read_raw", {"tag": "level", "limit": -1}, "limit: a whole number, zero or more, not -1"),
    ("history.read_raw", {"tag": "level", "continuation": "h1.bm9wZQ"}, "continuation: not a continuation of this historian"),
    ("history.read_raw", {"tag": "level", "when": 1}, "unknown argument 'when'"),
    ("history.read_processed", {"tag": "level", "start": EPOCH, "end": EPOCH + 10, "aggregate": "median"},
     "aggregate: one of interpolative, average, time_average"),
    ("history.read_processed", {"tag": "level", "start": EPOCH, "end": EPOCH, "aggregate": "average"}, "start and end are the same time"),
    ("history.read_processed", {"tag": "level", "start": EPOCH, "end": EPOCH + 1, "aggregate": "average",
                                "config": {"percent_data_bad": 101}}, "config: percent_data_bad must be a whole percentage 0..100"),
    ("history.read_processed", {"tag": "note", "start": EPOCH, "end": EPOCH + 1, "aggregate": "average"},
     "aggregate average needs a numeric tag; note is a string"),
    ("history.read_at_time", {"tag": "level", "times": "now"}, "times: a list of Unix seconds"),
    ("history.plot", {"tag": "level", "start": EPOCH, "end": EPOCH + 1, "max_points": 1}, "max_points: 2 to 10000, not 1"),
])
async def test_bad_arguments_are_refused_with_the_reason(plant, command, arguments, refusal) -> None:
    runtime, _ = plant
    with pytest.raises(CommandRefused) as refused:
        await runtime.commands.call(command, arguments, VIEWER)
    assert refusal in str(refused.value)


async def test_remote_callers_get_history_as_json_through_the_opcua_door(plant) -> None:
    _, server = plant
    async with client_for(server, "viewer") as client:
        commands = client.get_node(ua.NodeId("Commands", server.namespace_index))
        arguments = json.dumps({"tag": "level", "start": EPOCH, "end": EPOCH + 3})
        reply = json.loads(await commands.call_method(ua.NodeId("Commands.Call", server.namespace_index), "history.read_raw", arguments))
    assert reply == {"ok": True, "result": {"continuation": None, "samples": [
        {"time": EPOCH + t, "value": float(t), "quality": "good", "flags": []} for t in range(3)]}}
