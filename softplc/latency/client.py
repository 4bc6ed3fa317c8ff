"""The client side of the case IV handshake, run as its own process like any external program.

    python -m softplc.latency.client --protocol opcua --endpoint opc.tcp://127.0.0.1:4841/softplc/ --samples 100

It waits for Ready, answers with the next TaskID (1 → 2 → 3 → 1) and clears Ready, and prints
one JSON line per event on stdout with its `time.monotonic()` readings: when it saw Ready
(`t_seen`), started the write (`t_sent`) and had it acknowledged (`t_done`), plus what the PLC
reported for that handshake (Delay, DelayScans, Handshakes, ReadyStamp). `softplc latency`
starts it and reads these lines; nothing here knows about softplc's runtime.

After each answer, and outside the timed part, it waits until the PLC has taken it (Ready
low, or Handshakes counted on) and reads the PLC's figures for that handshake in one request.
The first answer is a warm-up: it may have been pending since before the client started.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time
from typing import Any, Callable, TextIO

from softplc.latency.driver import ROLES, Driver, DriverError, ReadyTracker, Snapshot
from softplc.latency.endpoint import EndpointError, parse_endpoint
from softplc.util.plurals import plural
from softplc.util.realtime import RealtimeError, cpu_list, format_cpus, set_cpu_affinity

Emit = Callable[[dict[str, Any]], None]
MAX_CONSECUTIVE_TIMEOUTS = 3


class HandshakeClient:
    """Answers Ready with the next TaskID until `samples` answers or `duration` seconds."""

    def __init__(self, driver: Driver, emit: Emit, *, samples: int | None, duration: float | None, timeout: float) -> None:
        if samples is None and duration is None:
            raise ValueError("give samples or duration")
        self.driver = driver
        self.emit = emit
        self.samples = samples
        self.duration = duration
        self.timeout = timeout
        self.answers = 0  # not counting the warm-up
        self.timeouts = 0
        self.tracker = ReadyTracker()

    def _finished(self, started: float) -> bool:
        if self.samples is not None and self.answers >= self.samples:
            return True
        return self.duration is not None and time.monotonic() - started >= self.duration

    async def run(self) -> None:
        driver = self.driver
        first = await driver.read()
        next_task = first.task_id % 3 + 1 if first.task_id in (1, 2, 3) else 1
        cpus = format_cpus(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else ""
        self.emit({"type": "hello", "pid": os.getpid(), "cpus": cpus, "driver": driver.description, "serves": sorted(driver.serves),
                   "task_id": first.task_id, "handshakes": first.handshakes, "t": time.monotonic()})
        before = first.handshakes  # the PLC's count before the next answer
        started = time.monotonic()
        consecutive = 0
        index = 0
        while index == 0 or not self._finished(started):
            driver.prepare(next_task)
            try:
                ready = await driver.wait_ready(self.tracker, self.timeout)
            except TimeoutError as error:
                self.timeouts += 1
                consecutive += 1
                self.emit({"type": "timeout", "index": index, "waited": self.timeout, "message": str(error), "t": time.monotonic()})
                if consecutive >= MAX_CONSECUTIVE_TIMEOUTS:
                    raise DriverError(f"no new Ready within {self.timeout:g} s, {plural(consecutive, 'time')} in a row: "
                                      f"is the PLC running the handshake? (the last time: {error})") from None
                continue
            consecutive = 0
            # The timed part: from seeing Ready to the write's acknowledgement, nothing else (an
            # OPC UA subscription answers where Ready arrives: then the driver timed it).
            t_sent = time.monotonic()
            ahead = await driver.answer(next_task)
            t_done = time.monotonic()
            if ahead is not None:  # sent where the driver saw Ready, timed there
                t_sent, t_done = ahead
            self.tracker.answered(ready)
            # Outside the timed part: tells `softplc latency` the client is alive (its watchdog).
            self.emit({"type": "answered", "index": index, "task_id": next_task, "t": t_done})
            # The first answer to a PLC that has no task yet starts the sequence: nothing is counted.
            starting = index == 0 and first.task_id not in (1, 2, 3)
            after = await driver.settle(ready, None if starting else before, self.timeout)
            status = self._report(index, next_task, ready, after, before, t_sent, t_done, starting)
            before = after.handshakes
            if index > 0:
                self.answers += 1
            index += 1
            if status == "missed" and after.ready:
                # Ready is still up: the PLC took neither the TaskID nor the clear. Answer it again.
                self.tracker = ReadyTracker()
                driver.rearm()
            # The next task follows the one the PLC holds (ours, unless it missed our answer).
            current = after.task_id if after.task_id in (1, 2, 3) else next_task
            next_task = current % 3 + 1
        self.emit({"type": "done", "answers": self.answers, "timeouts": self.timeouts, "t": time.monotonic()})

    def _report(self, index: int, task_id: int, ready: Snapshot, after: Snapshot, before: int | None,
                t_sent: float, t_done: float, starting: bool) -> str:
        """Emit the sample of one answer, with the PLC's figures as read after it took the answer."""
        counted = None if before is None or after.handshakes is None else after.handshakes - before
        if starting:
            status = "start"  # TaskID 0 → 1 starts the sequence; the PLC neither times nor counts it
        elif counted == 0 or (counted is None and after.ready):
            # Not counted, or (no counter) Ready still up after the wait: our clear of Ready lands
            # with the TaskID, so neither was applied.
            status = "missed"
        else:
            status = "ok"  # counted > 1: someone else answered too ("foreign")
        stamp = ready.ready_stamp if ready.ready_stamp is not None else after.ready_stamp
        # A stamp read after the answer (a subscription pushes Ready alone) is the answered Ready's
        # unless the client was held up longer than the PLC's next task: then the PLC has set its
        # next Ready, after the client saw this one. That stamp would make the delay short or
        # negative; the answered one's is unknown.
        lost = stamp is not None and stamp > ready.received
        self.emit({
            "type": "warmup" if index == 0 else "sample",
            "index": index,
            "task_id": task_id,
            "status": status,
            "ready_stamp": None if lost else stamp,
            "stamp_lost": lost,
            "t_seen": ready.received,
            "t_sent": t_sent,
            "t_done": t_done,
            "plc_handshakes": after.handshakes,
            "foreign": max(0, counted - 1) if counted is not None else 0,
            "plc_delay_ms": after.delay if status == "ok" else None,
            "plc_delay_scans": after.delay_scans if status == "ok" else None,
        })
        return status


def build_driver(args: argparse.Namespace) -> Driver:
    """The driver for --protocol, with the node ids or addresses given per role."""
    overrides = parse_tags(args.tag or [])
    if args.protocol == "opcua":
        from softplc.latency.opcua_driver import DEFAULT_NODE_IDS, OpcuaDriver

        node_ids = {**DEFAULT_NODE_IDS, **overrides}
        return OpcuaDriver(
            args.endpoint, node_ids, subscription=args.mode == "subscription",
            publishing_interval=args.publishing_interval, poll_interval=args.poll_interval / 1000.0,
            namespace=args.namespace, security=args.security, user=args.user, password=args.password,
        )
    from softplc.latency.modbus_driver import DEFAULT_ADDRESSES, ModbusDriver

    if args.mode == "subscription":
        raise DriverError("Modbus has no subscriptions: use --mode poll")
    try:
        endpoint = parse_endpoint(args.endpoint, "modbus")
    except EndpointError as error:
        raise DriverError(str(error)) from None
    addresses = {**DEFAULT_ADDRESSES, **overrides}
    return ModbusDriver(endpoint.host, endpoint.port, addresses, unit_id=args.unit_id, word_order=args.word_order, poll_interval=args.poll_interval / 1000.0)


def parse_tags(items: list[str]) -> dict[str, str]:
    """`ROLE=ADDRESS` items (e.g. `ready=ns=3;s=ROI_Ready`, `delay=holding:20:uint16`); `ROLE=` drops a role."""
    result: dict[str, str] = {}
    for item in items:
        role, sep, address = item.partition("=")
        role = role.strip().lower().replace("-", "_")
        if not sep or role not in ROLES:
            raise DriverError(f"bad --tag {item!r}; write ROLE=ADDRESS with ROLE one of: {', '.join(ROLES)}")
        result[role] = address.strip()
    return result


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m softplc.latency.client", description="Answer a PLC's Ready with the next TaskID; print JSON lines.")
    parser.add_argument("--protocol", choices=("opcua", "modbus"), required=True)
    parser.add_argument("--endpoint", required=True, help="opc.tcp://HOST:PORT/PATH or HOST:PORT (Modbus)")
    parser.add_argument("--mode", choices=("subscription", "poll"), default=None, help="default: subscription for OPC UA, poll for Modbus")
    parser.add_argument("--samples", type=int, help="stop after N answers (after one warm-up answer)")
    parser.add_argument("--duration", type=float, help="stop after S seconds")
    parser.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for a Ready before counting a timeout")
    parser.add_argument("--poll-interval", type=float, default=1.0, metavar="MS", help="polling period in ms (default 1)")
    parser.add_argument("--publishing-interval", type=float, default=0.0, metavar="MS", help="OPC UA publishing interval in ms (default 0: at once)")
    parser.add_argument("--tag", action="append", metavar="ROLE=ADDRESS", help="node id or Modbus address of a role (repeatable)")
    parser.add_argument("--namespace", help="OPC UA namespace URI for {ns} in node ids (default: urn:softplc:tags if the server has it, else its last)")
    parser.add_argument("--security", help="asyncua security string, e.g. Basic256Sha256,SignAndEncrypt,cert.pem,key.pem")
    parser.add_argument("--user")
    parser.add_argument("--password", default=os.environ.get("SOFTPLC_LATENCY_PASSWORD"))
    parser.add_argument("--unit-id", type=int, default=1)
    parser.add_argument("--word-order", choices=("big", "little"), default="big")
    parser.add_argument("--cpus", type=cpu_list, metavar="LIST", help="keep this client on these CPUs (e.g. 1; Linux)")
    return parser


def main(argv: list[str] | None = None, out: TextIO = sys.stdout) -> int:
    args = build_parser().parse_args(argv)
    if args.mode is None:
        args.mode = "subscription" if args.protocol == "opcua" else "poll"

    def emit(event: dict[str, Any]) -> None:
        out.write(json.dumps(event) + "\n")
        out.flush()

    if args.cpus is not None:
        try:
            set_cpu_affinity(args.cpus)
        except RealtimeError as error:
            emit({"type": "error", "message": f"--cpus: {error}", "t": time.monotonic()})
            return 1

    async def run() -> None:
        driver = build_driver(args)
        await driver.connect()
        try:
            await HandshakeClient(driver, emit, samples=args.samples, duration=args.duration, timeout=args.timeout).run()
        finally:
            await driver.close()

    try:
        asyncio.run(run())
    except DriverError as error:
        emit({"type": "error", "message": str(error), "t": time.monotonic()})
        return 1
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
