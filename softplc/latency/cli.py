"""`softplc latency`: measure the case IV handshake over OPC UA and Modbus TCP and report it like Table 8."""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from softplc.clients.login import LoginError, add_login_arguments, read_password
from softplc.latency.plant import SCENARIO_NAMES, PlantMissing, scenario_durations
from softplc.util.realtime import RealtimeError, check_cpus, cpu_list, set_cpu_affinity

if TYPE_CHECKING:
    from softplc.latency.results import Measurement
    from softplc.latency.target import Target

EXIT_OK, EXIT_FAILURE = 0, 1
MIN_SCAN_MS = 0.1  # the runtime's shortest task interval


def number(kind: type, *, low: float, inclusive: bool = True, high: float | None = None, unit: str = "") -> Any:
    """An argparse type: a finite `kind` ≥ low (> low unless `inclusive`) and ≤ high, or a clear message."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'a whole number' if kind is int else 'a number'}") from None
        too_low = value < low if inclusive else value <= low
        if not math.isfinite(value) or too_low or (high is not None and value > high):
            limits = f"from {low:g} to {high:g}" if high is not None else f"at least {low:g}" if inclusive else f"more than {low:g}"
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {limits}{unit}")
        return value

    return parse


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
    amount.add_argument("--samples", type=number(int, low=1), metavar="N", help="handshakes to measure per run (default 100)")
    amount.add_argument("--duration", type=number(float, low=0, inclusive=False, unit=" s"), metavar="S",
                        help="measure for S seconds per run instead")
    parser.add_argument("--scan", type=number(float, low=MIN_SCAN_MS, unit=" ms (the runtime's shortest task interval is 100us)"),
                        default=10.0, metavar="MS",
                        help="the PLC's scan in ms (default 10, the thesis's; at least 0.1); with --endpoint: what the remote PLC runs")
    parser.add_argument("--client", choices=("subscription", "poll", "link"),
                        help="OPC UA client mode (default subscription; Modbus always polls); link: a second softplc runtime "
                        "answers, joined to ours by a link of --protocol (PLC to PLC, programs/handshake_answer.yaml)")
    parser.add_argument("--poll-interval", type=number(float, low=0, inclusive=False, unit=" ms"), default=1.0, metavar="MS",
                        help="client polling period (default 1 ms)")
    parser.add_argument("--publishing-interval", type=number(float, low=0, unit=" ms"), default=0.0, metavar="MS",
                        help="OPC UA subscription publishing interval (default 0: publish at once)")
    parser.add_argument("--endpoint", metavar="URL",
                        help="measure this server instead of starting ours: opc.tcp://HOST:PORT[/PATH] (OPC UA) or HOST:PORT "
                        "(Modbus; also modbus://HOST:PORT)")
    parser.add_argument("--tag", action="append", default=[], metavar="ROLE=ADDRESS",
                        help="with --endpoint: where a role lives, e.g. ready=ns=4;s=MAIN.ROI_Ready or task_id=holding:1 "
                        "(roles: ready, task_id, delay, delay_scans, handshakes, ready_stamp; ROLE= drops one)")
    parser.add_argument("--namespace", metavar="URI", help="OPC UA namespace URI for {ns} in node ids "
                        "(default: urn:softplc:tags if the server has it, else the server's last)")
    # The login options every OPC UA client command shares (--endpoint and --timeout are latency's own).
    add_login_arguments(
        parser, endpoint=False, timeout=False, password_env="SOFTPLC_LATENCY_PASSWORD",
        user_help="; add an operator with `softplc users add NAME --role operator --config CONFIG`",
        security_help="OPC UA security: None, Sign or SignAndEncrypt (Basic256Sha256), optionally with the client "
        "certificate and key files; without them one is made (our runtime trusts it itself; another server "
        "must trust ~/.softplc/latency-client/latency-client.der)",
    )
    parser.add_argument("--unit-id", type=number(int, low=0, high=255), default=1, help="Modbus unit id (default 1)")
    parser.add_argument("--word-order", choices=("big", "little"), default="big", help="Modbus word order of 32/64-bit values")
    parser.add_argument("--timeout", type=number(float, low=0, inclusive=False, unit=" s"), metavar="S",
                        help="wait this long for a Ready before counting a timeout "
                        "(default: the scenario's longest task + 1 s; must be longer than that task)")
    parser.add_argument("--loop", choices=("asyncio", "uvloop"), default="asyncio", help="event loop of our runtime (default asyncio)")
    parser.add_argument("--cpus", type=cpu_list, metavar="LIST",
                        help="keep our runtime on these CPUs (e.g. 0; Linux), as `softplc run --cpus`")
    parser.add_argument("--client-cpus", type=cpu_list, metavar="LIST",
                        help="keep the client process on these CPUs (e.g. 1): with --cpus, each side on a CPU of its "
                        "own, as a soft PLC is deployed; left out, the operating system places both")
    parser.add_argument("--out", type=Path, metavar="DIR", help="write samples.csv, statistics.json, report.txt and PNG figures here")
    parser.add_argument("--json", action="store_true", help="print the statistics as JSON on stdout (the table goes to stderr)")
    parser.set_defaults(func=cmd_latency)


def targets(args: argparse.Namespace) -> list[Target]:
    """One Target per protocol × scenario asked for; raises ValueError on a contradiction."""
    from softplc.latency.endpoint import guess_protocol, parse_endpoint
    from softplc.latency.target import Target

    protocols = ["opcua", "modbus"] if args.protocol == "all" else [args.protocol]
    if args.endpoint is not None:
        if args.protocol == "all":
            protocols = [guess_protocol(args.endpoint)]
        elif args.protocol != guess_protocol(args.endpoint):
            raise ValueError(f"--endpoint {args.endpoint} does not look like {args.protocol}: write opc.tcp://HOST:PORT[/PATH] "
                             "for OPC UA, HOST:PORT for Modbus")
        parse_endpoint(args.endpoint, protocols[0])  # EndpointError (a ValueError) says what is wrong
    elif args.tag:
        raise ValueError("--tag is for --endpoint: our own handshake plant has its tags where the client expects them")
    if args.cpus is not None and args.endpoint is not None:
        raise ValueError("--cpus places our runtime, which --endpoint does not start: leave it out (--client-cpus places the client)")
    for cpus in (args.cpus, args.client_cpus):
        if cpus is not None:
            try:
                check_cpus(cpus)
            except RealtimeError as error:
                raise ValueError(str(error)) from None
    _check_tags(args.tag, protocols)
    if args.client == "link" and args.endpoint is not None:
        raise ValueError("--client link runs both runtimes here: leave out --endpoint")
    if args.protocol == "modbus" and args.client == "subscription":
        raise ValueError("Modbus has no subscriptions: leave out --client or use --client poll")
    if args.security and "opcua" not in protocols:
        raise ValueError("--security is for OPC UA")
    security = args.security.text() if args.security else None  # checked by argparse already
    scenarios = list(SCENARIO_NAMES) if args.scenario == "all" else [args.scenario]
    if args.timeout is not None:
        for scenario in scenarios:
            longest = max(scenario_durations(scenario))
            if args.timeout <= longest:
                raise ValueError(f"--timeout {args.timeout:g} s is not longer than the {scenario} scenario's longest task "
                                 f"({longest:g} s): a Ready comes only after it (default: {longest + 1:g} s)")
    samples = args.samples if args.samples is not None or args.duration is not None else 100
    try:
        password = read_password(args)
    except LoginError as error:
        raise ValueError(str(error)) from None
    result = []
    for scenario in scenarios:
        for protocol in protocols:
            result.append(Target(
                protocol=protocol, scenario=scenario, scan=args.scan / 1000.0,
                client_mode=args.client if protocol == "opcua" or args.client == "link" else None,
                endpoint=args.endpoint, samples=samples, duration=args.duration, tags=list(args.tag),
                namespace=args.namespace, security=security, user=args.user, password=password,
                unit_id=args.unit_id, word_order=args.word_order, poll_interval_ms=args.poll_interval,
                publishing_interval_ms=args.publishing_interval, timeout=args.timeout, loop=args.loop,
                client_cpus=args.client_cpus,
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


def cmd_latency(args: argparse.Namespace) -> int:
    try:
        return _latency(args)
    except KeyboardInterrupt:  # e.g. while the options are checked, or a second Ctrl-C
        print("\nsoftplc latency: interrupted by the user", file=sys.stderr)
        return EXIT_FAILURE


class EarlyInterrupt:
    """Notes a Ctrl-C that comes before the runs' event loop handles it (while that loop starts)."""

    def __init__(self) -> None:
        self.requested = False

    def __call__(self, signum: int, frame: Any) -> None:
        self.requested = True


def _latency(args: argparse.Namespace) -> int:
    from softplc.latency.progress import estimate_seconds, plural

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
    if args.cpus is not None:
        try:
            set_cpu_affinity(args.cpus)
        except RealtimeError as error:
            print(f"softplc latency: --cpus: {error}", file=sys.stderr)
            return EXIT_FAILURE
    loop_factory = None
    if args.loop == "uvloop":
        try:
            import uvloop
        except ImportError:
            print("softplc latency: --loop uvloop needs the uvloop package: pip install uvloop", file=sys.stderr)
            return EXIT_FAILURE
        loop_factory = uvloop.new_event_loop
    early = EarlyInterrupt()
    previous = signal.signal(signal.SIGINT, early)
    try:
        print(f"softplc latency: {plural(len(plan), 'run')}, about {_minutes(total)} "
              f"({'--endpoint ' + args.endpoint if args.endpoint else 'our runtime in real time, the client in its own process'})",
              file=sys.stderr)
        with asyncio.Runner(loop_factory=loop_factory) as runner:
            measurements = runner.run(_run_all(plan, early))
    finally:
        signal.signal(signal.SIGINT, previous)
    report_stream = sys.stderr if args.json else sys.stdout
    _report(measurements, args, report_stream)
    problems = [m for m in measurements if not m.complete]
    return EXIT_OK if not problems and measurements else EXIT_FAILURE


async def _run_all(plan: list[Target], early: EarlyInterrupt | None = None) -> list[Measurement]:
    from softplc.latency.measurement import measure
    from softplc.latency.progress import ProgressBar, plural

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()

    def interrupt() -> None:
        # The first Ctrl-C ends the run and reports it; a second one quits at once.
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, interrupt)
        except (NotImplementedError, RuntimeError):
            pass
    if early is not None and early.requested:
        stop.set()
    measurements: list[Measurement] = []
    for index, target in enumerate(plan):
        if stop.is_set():
            print(f"softplc latency: interrupted by the user; {plural(len(plan) - index, 'run')} not started", file=sys.stderr)
            break
        bar = ProgressBar(target, sys.stderr)
        redraw = asyncio.create_task(bar.redraw())
        try:
            result = await measure(target, bar.update, stop)
        finally:
            redraw.cancel()
            await asyncio.gather(redraw, return_exceptions=True)
        bar.finish(result)
        measurements.append(result)
    return measurements


def _report(measurements: list[Measurement], args: argparse.Namespace, stream: TextIO) -> None:
    from softplc.latency.report import print_report, to_json, write_csv

    statistics = {"runs": [to_json(m) for m in measurements]}
    # A run that never reached the PLC has nothing to tabulate: its line above said why.
    if any(m.connected for m in measurements):
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
