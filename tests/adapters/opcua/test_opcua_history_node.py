"""An independent client none of us wrote (node-opcua) reads history from softplc: raw with continuation points,
processed Average, at time (issue 16, OPC UA); the plant of tests/opcua_history_support.py."""

from __future__ import annotations

from asyncua import ua

from tests.adapters.opcua.test_opcua_node import _require_node_opcua, _run
from tests.opcua_history_support import EPOCH, recorded_plant
from tests.opcua_support import PASSWORDS

S = ua.StatusCodes
MS = int(EPOCH * 1000)


def _ms(seconds: float) -> int:
    return MS + int(seconds * 1000)


async def test_node_opcua_reads_raw_processed_and_at_time_history(tmp_path) -> None:
    node = _require_node_opcua()
    async with recorded_plant(tmp_path) as (_, server):
        code, seen, output = await _run(node, server.endpoint, "viewer", PASSWORDS["viewer"], str(MS), script="history_check.js")
    assert code == 0 and seen is not None, output
    assert seen["historizing"] is True and seen["accessLevel"] & 4
    # Raw: 25 values (0..24 s), 10 a page, each once, in order, Good.
    pages = seen["rawPages"]
    assert [len(page["rows"]) for page in pages] == [10, 10, 5] and all(page["status"] == "Good" for page in pages)
    assert [row for page in pages for row in page["rows"]] == [[_ms(t), t, 0] for t in range(25)]
    assert seen["bogusPoint"] == "BadContinuationPointInvalid"
    # Processed: Part 13 Average (the mean of the raw values) and Maximum, Good + HistorianCalculated.
    assert seen["average"]["rows"] == [[_ms(0), 4.5, 0x401], [_ms(10), 14.5, 0x401], [_ms(20), 24.5, 0x401]]
    assert seen["maximum"]["rows"] == [[_ms(0), 9, 0x401], [_ms(10), 19, 0x401], [_ms(20), 29, 0x401]]
    assert seen["pressureAverage"] == [[_ms(0), 22.5, S.UncertainDataSubNormal | 0x401]]  # bad and uncertain values left out
    assert seen["total"] == "BadAggregateNotSupported"
    # At time: interpolated (HistorianInterpolated), raw, Bad_NoData before the history; simple bounds refuse a bad neighbour.
    assert seen["levelAt"] == [[_ms(2.5), 2.5, 0x402], [_ms(7), 7, 0], [_ms(25), 25, 0], [_ms(-10), None, S.BadNoData]]
    assert seen["pressureAt"] == [[_ms(25), 25, S.UncertainDataSubNormal | 0x402]]
    assert seen["pressureSimple"] == [[_ms(25), None, S.BadNoData]]
    assert seen["aggregateFunctions"] == sorted(["Average", "Count", "Interpolative", "Maximum", "MaximumActualTime", "Minimum",
                                                 "MinimumActualTime", "TimeAverage2"])
    assert seen["maxReturnDataValues"] == 1000
