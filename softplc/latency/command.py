"""`softplc latency`: measure the case IV handshake over OPC UA and Modbus TCP and report it like Table 8."""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from softplc.latency.plant import SCENARIO_NAMES, PlantMissing, scenario_durations

if TYPE_CHECKING:
    from softplc.latency.measurement import Measurement, Target

EXIT_OK, EXIT_FAILURE = 0, 1


def add_commands(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = commands.add_parser(
        "latency",
        help="measure the PLC↔client handshake latency (thesis case study IV)",
        description="Run the case IV handshake: the PLC sets Ready when a timed task is done, a client in a "
        "separate process answers with the next TaskID over OPC UA or Modbus TCP, and the PLC measures the delay. "
        "By default our runtime serves the handshake plant (programs/handshake.yaml) in real time on a free "
        "loopback port; --endpoint measures another server instead. Reports the thesis's Table 8 beside ours.",
        epilog="Examples: softplc latency | softplc latency --protocol opcua --scenario average --samples 300 --out results/ | "
        "softplc latency --protocol modbus --endpoint 192.168.0.10:502 --tag ready=coil:0 --tag task_id=holding:0 "
        "--tag delay=holding:1:uint16",
    )
    parser.add_argument("--protocol", choices=("opcua", "modbus", "all"), default="all", help="default: all")
    parser.add_argument("--scenario", choices=(*SCENARIO_NAMES, "all"), default="fast",
                        help="task durations: slow 10/20/30 s, average 1/2/5 s, fast 100/200/500 ms (default fast)")
    amount = parser.add_mutually_exclusive_group()
    amount.add_argument("--samples", type=int, metavar="N", help="handshakes to measure per run (default 100)")
    amount.add_argument("--duration", type=float, metavar="S", help="measure for S seconds per run instead")
    parser.add_argument("--scan", type=float, default=10.0, metavar="MS",
                        help="the PLC's scan in ms (default 10, the thesis's); with --endpoint: what the remote PLC runs")
    parser.add_argument("--client", choices=("subscription", "poll"), help="OPC UA client mode (default subscription; Modbus always polls)")
    parser.add_argument("--poll-interval", type=float, default=1.0, metavar="MS", help="client polling period (default 1 ms)")
    parser.add_argument("--publishing-interval", type=float, default=0.0, metavar="MS",
                        help="OPC UA subscription publishing interval (default 0: publish at once)")
    parser.add_argument("--endpoint", metavar="URL", help="measure this server instead of starting ours: opc.tcp://HOST:PORT/PATH or HOST:PORT (Modbus)")
    parser.add_argument("--tag", action="append", default=[], metavar="ROLE=ADDRESS",
                        help="with --endpoint: where a role lives, e.g. ready=ns=4;s=MAIN.ROI_Ready or task_id=holding:1 "
                        "(roles: ready, task_id, delay, delay_scans, handshakes, ready_stamp; ROLE= drops one)")
    parser.add_argument("--namespace", metavar="URI", help="OPC UA namespace URI for {ns} in node ids (default: the server's last)")
    parser.add_argument("--security", metavar="MODE[,CERT,KEY]",
                        help="OPC UA security: None, Sign or SignAndEncrypt (Basic256Sha256), optionally with the client "
                        "certificate and key files; without them one is made (our runtime trusts it itself; another server "
                        "must trust ~/.softplc/latency-client/latency-client.der)")
    parser.add_argument("--user", help="OPC UA user name (password from $SOFTPLC_LATENCY_PASSWORD)")
    parser.add_argument("--unit-id", type=int, default=1, help="Modbus unit id (default 1)")
    parser.add_argument("--word-order", choices=("big", "little"), default="big", help="Modbus word order of 32/64-bit values")
    parser.add_argument("--timeout", type=float, metavar="S", help="wait this long for a Ready before counting a timeout "
                        "(default: the scenario's longest task + 1 s)")
    parser.add_argument("--loop", choices=("asyncio", "uvloop"), default="asyncio", help="event loop of our runtime (default asyncio)")
    parser.add_argument("--out", type=Path, metavar="DIR", help="write samples.csv, statistics.json, report.txt and PNG figures here")
    parser.add_argument("--json", action="store_true", help="print the statistics as JSON on stdout (the table goes to stderr)")
    parser.set_defaults(func=cmd_latency)


def targets(args: argparse.Namespace) -> list[Target]:
    """One Target per protocol × scenario asked for; raises ValueError on a contradiction."""
    from softplc.latency.measurement import Target

    protocols = ["opcua", "modbus"] if args.protocol == "all" else [args.protocol]
    if args.endpoint:
        if args.protocol == "all":
            guessed = "opcua" if args.endpoint.startswith("opc.tcp://") else "modbus"
            protocols = [guessed]
        elif (args.protocol == "opcua") != args.endpoint.startswith("opc.tcp://"):
            raise ValueError(f"--endpoint {args.endpoint} does not look like {args.protocol}: write opc.tcp://HOST:PORT/PATH for OPC UA, HOST:PORT for Modbus")
    elif args.tag:
        raise ValueError("--tag is for --endpoint: our own handshake plant has its tags where the client expects them")
    _check_tags(args.tag, protocols)
    if args.protocol == "modbus" and args.client == "subscription":
        raise ValueError("Modbus has no subscriptions: leave out --client or use --client poll")
    if args.security:
        from softplc.latency.certificate import Security

        if "opcua" not in protocols:
            raise ValueError("--security is for OPC UA")
        Security.parse(args.security)  # raises ValueError with the reason
    if args.scan <= 0:
        raise ValueError("--scan must be positive")
    if args.samples is not None and args.samples < 1:
        raise ValueError("--samples must be at least 1")
    if args.duration is not None and args.duration <= 0:
        raise ValueError("--duration must be positive")
    scenarios = list(SCENARIO_NAMES) if args.scenario == "all" else [args.scenario]
    samples = args.samples if args.samples is not None or args.duration is not None else 100
    result = []
    for scenario in scenarios:
        for protocol in protocols:
            result.append(Target(
                protocol=protocol, scenario=scenario, scan=args.scan / 1000.0,
                client_mode=None if protocol == "modbus" else args.client,
                endpoint=args.endpoint, samples=samples, duration=args.duration, tags=list(args.tag),
                namespace=args.namespace, security=args.security, user=args.user, password=_password(args),
                unit_id=args.unit_id, word_order=args.word_order, poll_interval_ms=args.poll_interval,
                publishing_interval_ms=args.publishing_interval, timeout=args.timeout, loop=args.loop,
            ))
    return result


def _check_tags(items: list[str], protocols: list[str]) -> None:
    """Refuse a malformed --tag before anything starts."""
    from softplc.latency.client import parse_tags
    from softplc.latency.driver import DriverError
    from softplc.latency.modbus_driver import Address

    try:
        tags = parse_tags(items)
        if "modbus" in protocols:
            for role, text in tags.items():
                if text:
                    Address.parse(text, role)
    except DriverError as error:
        raise ValueError(str(error)) from None
    for role in ("ready", "task_id"):
        if role in tags and not tags[role]:
            raise ValueError(f"--tag {role}= cannot drop {role}: the handshake needs it")


def _password(args: argparse.Namespace) -> str | None:
    import os

    return os.environ.get("SOFTPLC_LATENCY_PASSWORD") if args.user else None


def estimate_seconds(target: Target) -> float:
    """Roughly how long a run takes: three tasks per cycle of the scenario."""
    if target.duration is not None:
        return target.duration
    durations = scenario_durations(target.scenario)
    return (target.samples or 0) * sum(durations) / 3 + 3.0


def cmd_latency(args: argparse.Namespace) -> int:
    try:
        plan = targets(args)
        total = sum(estimate_seconds(target) for target in plan)
    except (ValueError, PlantMissing) as error:
        print(f"softplc latency: {error}", file=sys.stderr)
        return EXIT_FAILURE
    if args.out is not None:
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            print(f"softplc latency: cannot create --out {args.out}: {error}", file=sys.stderr)
            return EXIT_FAILURE
    loop_factory = None
    if args.loop == "uvloop":
        try:
            import uvloop
        except ImportError:
            print("softplc latency: --loop uvloop needs the uvloop package: pip install uvloop", file=sys.stderr)
            return EXIT_FAILURE
        loop_factory = uvloop.new_event_loop
    print(f"softplc latency: {len(plan)} run{'s' if len(plan) != 1 else ''}, about {_minutes(total)} "
          f"({'--endpoint ' + args.endpoint if args.endpoint else 'our runtime in real time, the client in its own process'})",
          file=sys.stderr)
    with asyncio.Runner(loop_factory=loop_factory) as runner:
        measurements = runner.run(_run_all(plan))
    report_stream = sys.stderr if args.json else sys.stdout
    _report(measurements, args, report_stream)
    problems = [m for m in measurements if not m.complete]
    return EXIT_OK if not problems and measurements else EXIT_FAILURE


async def _run_all(plan: list[Target]) -> list[Measurement]:
    from softplc.latency.measurement import measure

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError):
            pass
    measurements: list[Measurement] = []
    for target in plan:
        if stop.is_set():
            break
        bar = ProgressBar(target, sys.stderr)
        result = await measure(target, bar.update, stop)
        bar.finish(result)
        measurements.append(result)
    return measurements


def _report(measurements: list[Measurement], args: argparse.Namespace, stream: TextIO) -> None:
    from softplc.latency.report import print_report, to_json, write_csv

    statistics = {"runs": [to_json(m) for m in measurements]}
    print_report(measurements, stream)
    if args.json:
        print(json.dumps(statistics, indent=2, default=_jsonable))
    if args.out is not None:
        import io

        from softplc.latency.figures import write_figure

        write_csv(measurements, args.out / "samples.csv")
        (args.out / "statistics.json").write_text(json.dumps(statistics, indent=2, default=_jsonable) + "\n")
        text = io.StringIO()
        print_report(measurements, text)
        (args.out / "report.txt").write_text(text.getvalue())
        figures = [write_figure(m, args.out) for m in measurements]
        print(f"wrote {args.out}/samples.csv, statistics.json, report.txt and {len(figures)} figure{'s' if len(figures) != 1 else ''}",
              file=sys.stderr)


def _jsonable(value: Any) -> Any:
    if hasattr(value, "to_dict"):
        return value.to_dict()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def _minutes(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min"


class ProgressBar:
    """A one-line progress bar with ETA on stderr (only on a terminal; otherwise start and end lines)."""

    def __init__(self, target: Target, stream: TextIO) -> None:
        self.target = target
        self.stream = stream
        self.live = stream.isatty()
        self.last_draw = 0.0
        self.announced = False

    def update(self, run: Measurement) -> None:
        if not self.announced:
            self.announced = True
            print(f"{self.target.label}: client process {run.client_pid} measuring {run.endpoint}", file=self.stream, flush=True)
        now = time.monotonic()
        if not self.live or now - self.last_draw < 0.2:
            return
        self.last_draw = now
        target = self.target
        done = len(run.samples)
        if target.duration is not None:
            fraction = min(1.0, run.wall_seconds / target.duration)
            count = f"{done} samples"
        else:
            fraction = min(1.0, done / (target.samples or 1))
            count = f"{done}/{target.samples} samples"
        eta = run.wall_seconds * (1 - fraction) / fraction if fraction > 0 else estimate_seconds(target)
        width = 28
        filled = int(width * fraction)
        last = run.samples[-1] if run.samples else None
        figures = ""
        if last is not None and last.plc_delay_ms is not None:
            figures = f"  last: PLC {last.plc_delay_ms:.0f} ms"
            hires = last.hires_ms(run.same_clock)
            if hires is not None:
                figures += f", hi-res {hires:.2f} ms"
        trouble = f"  missed {run.missed} timeouts {run.timeouts}" if run.missed or run.timeouts else ""
        line = f"\r{target.label:14s} [{'#' * filled}{'.' * (width - filled)}] {count}  ETA {_clock(eta)}{figures}{trouble}"
        print(line + "\033[K", end="", file=self.stream, flush=True)

    def finish(self, run: Measurement) -> None:
        if self.live and self.announced:
            print(file=self.stream)
        state = "done" if run.complete else "INCOMPLETE: " + "; ".join(run.errors)
        print(f"{self.target.label}: {len(run.ok_samples)} samples in {run.wall_seconds:.0f} s — {state}", file=self.stream, flush=True)


def _clock(seconds: float) -> str:
    seconds = max(0, int(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    return f"{seconds // 60}m{seconds % 60:02d}s"
