"""How much slower a code path runs when it last ran a while ago: asyncua's decoding, warm and cold.

The case IV handshake serves one request every 100-500 ms; a benchmark loop serves them back to
back. This measures the difference on this machine without any network: the time asyncua takes to
decode a PublishResponse of one value (what a client does with each notification) and to encode a
WriteRequest of the answer's shape (uint16 + bool), run

- back to back (the code and its data stay in the CPU's caches),
- once after each gap of `--gap` ms spent sleeping (the process blocked, as a server between requests),
- once after each gap spent spinning on the clock (the process never leaves the CPU).

If the two gapped figures are both well above the back-to-back one, what slows a sparse request is
the CPU caches (shared with other processes and, in a VM, other machines), not the process being
woken: a scheduling or loop change cannot win it back, only less work on the path can.

Beside each asyncua path, softplc's short way for the same message: the latency client's decoding
(`softplc/latency/response_decoding.py`) and the server's encoding of a PublishResponse whose value
is a tag change encoded for the first time (`softplc/adapters/opcua/response_encoding.py`).

    .venv/bin/python bench/cold_path.py [--gap 100] [--count 60]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from asyncua import ua
from asyncua.ua.ua_binary import struct_from_binary, struct_to_binary

from softplc.adapters.opcua.response_encoding import encode_response
from softplc.core.tags import Quality
from softplc.latency.response_decoding import decode_publish_response
from softplc.protocols.opcua_variants import tag_data_value


def publish_response(value: ua.DataValue | None = None) -> ua.PublishResponse:
    """A PublishResponse of one Boolean, as the server sends Ready's change."""
    if value is None:
        value = tag_data_value(True, ua.VariantType.Boolean, Quality.GOOD, 1_795_000_000.0)
    message = ua.NotificationMessage(SequenceNumber=5, NotificationData=[
        ua.DataChangeNotification(MonitoredItems=[ua.MonitoredItemNotification(ClientHandle=201, Value=value)])])
    result = ua.PublishResult(SubscriptionId=1, AvailableSequenceNumbers=[5], NotificationMessage=message, Results=[ua.StatusCode()])
    return ua.PublishResponse(Parameters=result)


def fresh_changes(count: int) -> Callable[[], ua.PublishResponse]:
    """Each call: the next of `count` PublishResponses, each with a tag change not encoded yet."""
    responses = iter([publish_response() for _ in range(count)])
    return lambda: next(responses)


def write_request() -> ua.WriteRequest:
    items = [ua.WriteValue(NodeId=ua.NodeId("task_id", 2), AttributeId=ua.AttributeIds.Value,
                           Value=ua.DataValue(ua.Variant(2, ua.VariantType.UInt16))),
             ua.WriteValue(NodeId=ua.NodeId("ready", 2), AttributeId=ua.AttributeIds.Value,
                           Value=ua.DataValue(ua.Variant(False, ua.VariantType.Boolean)))]
    return ua.WriteRequest(Parameters=ua.WriteParameters(NodesToWrite=items))


def spin(seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def timed(work: Callable[[], object], count: int, wait: Callable[[float], None] | None, gap: float) -> list[float]:
    """Microseconds of each of `count` runs of `work`, each after `wait(gap)` (none: back to back)."""
    work()
    durations = []
    for _ in range(count):
        if wait is not None:
            wait(gap)
        started = time.perf_counter()
        work()
        durations.append((time.perf_counter() - started) * 1e6)
    return durations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gap", type=float, default=100.0, help="ms between two runs of the gapped cases (default 100)")
    parser.add_argument("--count", type=int, default=60, help="runs per gapped case (default 60; back to back: 2,000)")
    args = parser.parse_args()
    if args.gap <= 0 or args.count < 1:
        parser.error("--gap must be > 0 and --count >= 1")
    gap = args.gap / 1000
    response = publish_response()
    encoded = struct_to_binary(response)
    request = write_request()
    changes = fresh_changes(2 * args.count + 2010)  # timed() runs each path once more per case
    paths = {"decode a PublishResponse": lambda: struct_from_binary(ua.PublishResponse, ua.utils.Buffer(encoded)),
             "  softplc's latency client": lambda: decode_publish_response(ua.utils.Buffer(encoded)),
             "encode a PublishResponse": lambda: struct_to_binary(response),
             "  softplc's server": lambda: encode_response(changes()),
             "encode a WriteRequest": lambda: struct_to_binary(request)}
    print(f"microseconds per run (median / mean); gapped runs {args.gap:g} ms apart, {args.count} each")
    print(f"{'path':26s} {'back to back':>16s} {'after a sleep':>16s} {'after a spin':>16s}  cold ÷ warm")
    for name, work in paths.items():
        warm = timed(work, 2000, None, 0.0)
        slept = timed(work, args.count, time.sleep, gap)
        spun = timed(work, args.count, spin, gap)
        row = [f"{statistics.median(xs):7.1f} / {statistics.fmean(xs):6.1f}" for xs in (warm, slept, spun)]
        ratio = statistics.median(slept) / statistics.median(warm)
        print(f"{name:26s} {row[0]:>16s} {row[1]:>16s} {row[2]:>16s}  {ratio:5.1f} ×")


if __name__ == "__main__":
    main()
