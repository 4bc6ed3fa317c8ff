"""The client process of one measurement: start it, follow its reports, and account for its end.

The client (`python -m softplc.latency.client`) prints one JSON line per event. A client that
reports nothing for too long hangs and is killed. When it dies or hangs, the PLC is read once
more: a Ready it left unanswered is missed (noted with when it was set), switches it never
reported are unreported. That wait is announced and ends at Ctrl-C.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import os
import sys
import time
from pathlib import Path

from softplc.latency.results import Measurement, Progress, Sample, interrupted
from softplc.latency.target import Target
from softplc.util.realtime import format_cpus

log = logging.getLogger(__name__)

# A client that reports nothing for longer than this is hung (e.g. stopped with SIGSTOP) and is
# killed. Between two of its reports lies at most one wait of the handshake timeout plus a few
# requests (each with its own timeout of a few seconds): hence the timeout plus a margin.
WATCHDOG_MARGIN = 10.0
CONNECT_ALLOWANCE = 30.0  # s for the client process to start, connect and say hello


async def run_client(target: Target, result: Measurement, progress: Progress, stop: asyncio.Event) -> None:
    started = time.monotonic()
    env = dict(os.environ)
    if target.password:
        env["SOFTPLC_LATENCY_PASSWORD"] = target.password
    # The client must import this very softplc, wherever the command was started from.
    package_root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = package_root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    process = await asyncio.create_subprocess_exec(
        *client_command(target, result.endpoint), stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=env
    )
    result.client_pid = process.pid
    log.debug("client process %d started: %s", process.pid, target.label)
    stderr_tail: collections.deque[str] = collections.deque(maxlen=40)
    stderr_task = asyncio.create_task(_drain(process.stderr, stderr_tail))
    done = hung = client_error = False
    last_handshakes: int | None = None
    assert process.stdout is not None

    async def interrupt() -> None:
        await stop.wait()
        interrupted(result, stop)
        await _end_process(process)

    interrupter = asyncio.create_task(interrupt())
    try:
        while True:
            allowance = target.ready_timeout() + WATCHDOG_MARGIN if result.connected else CONNECT_ALLOWANCE
            try:
                raw = await asyncio.wait_for(process.stdout.readline(), allowance)
            except TimeoutError:
                hung = True
                why = f"the handshake timeout {target.ready_timeout():g} s + {WATCHDOG_MARGIN:g} s" if result.connected else "while starting"
                result.errors.append(f"the client process {process.pid} reported nothing for {allowance:g} s ({why}): "
                                     "it hangs and was killed")
                process.kill()
                break
            if not raw:
                break
            try:
                event = json.loads(raw)
            except json.JSONDecodeError:
                stderr_tail.append(raw.decode(errors="replace").rstrip())
                continue
            kind = event.get("type")
            if kind == "hello":
                result.connected = True
                result.driver = event.get("driver", "")
                last_handshakes = event.get("handshakes")
                if target.client_cpus is not None and event.get("cpus"):
                    result.conditions["client_cpus"] = event["cpus"]  # where the client says it runs
            elif kind in ("sample", "warmup"):
                sample = Sample.from_event(event)
                (result.samples if kind == "sample" else result.warmup).append(sample)
                if sample.status == "missed" and kind == "sample":
                    result.missed += 1
                result.foreign += int(event.get("foreign") or 0)
                result.stamps_lost += bool(event.get("stamp_lost")) and kind == "sample"
                if sample.plc_handshakes is not None:
                    last_handshakes = sample.plc_handshakes
            elif kind == "timeout":
                result.timeouts += 1
            elif kind == "error":
                client_error = True
                result.errors.append(str(event.get("message")))
            elif kind == "done":
                done = True
            result.wall_seconds = time.monotonic() - started
            progress(result)
        result.client_exit = await process.wait()
    except asyncio.CancelledError:
        process.kill()
        await process.wait()
        raise
    finally:
        result.client_gone_at = time.monotonic()
        interrupter.cancel()
        await stderr_task
        result.client_stderr = list(stderr_tail)
        result.wall_seconds = time.monotonic() - started
    if done or interrupted(result, stop):
        result.ended = result.ended or "complete"
        return
    if hung:
        result.ended = "client hung"
    elif client_error:
        result.ended = "client stopped on an error"
    else:
        exit_code = result.client_exit or 0
        result.ended = "client died"
        last_words = next((line for line in reversed(stderr_tail) if line.strip()), "")
        if exit_code < 0:
            result.errors.append(f"the client process was killed by signal {-exit_code}")
        elif not result.errors:
            result.errors.append(f"the client process exited with code {exit_code} before finishing"
                                 + (f": {last_words}" if last_words else ""))
    # A client that stopped on its own error said why; one that never connected left nothing to
    # account for. Otherwise the PLC may hold a Ready nobody will answer: count it.
    if result.connected and not client_error:
        await _reconcile(target, result, last_handshakes, progress, stop)


async def _end_process(process: asyncio.subprocess.Process, grace: float = 3.0) -> None:
    """Terminate the client; kill it if it does not go (a stopped process ignores SIGTERM)."""
    if process.returncode is not None:
        return
    process.terminate()
    try:
        await asyncio.wait_for(process.wait(), grace)
    except TimeoutError:
        process.kill()


async def _drain(stream: asyncio.StreamReader | None, tail: collections.deque[str]) -> None:
    if stream is None:
        return
    async for line in stream:
        tail.append(line.decode(errors="replace").rstrip())


async def _reconcile(target: Target, result: Measurement, last_handshakes: int | None, progress: Progress, stop: asyncio.Event) -> None:
    """After the client died: count the Ready it left unanswered and the answers it never reported.

    Waits (up to the handshake timeout) for the PLC to set its next Ready; says so, and stops
    waiting when the user asks to."""
    wait = target.ready_timeout()
    result.activity = (f"{target.label}: the client is gone; reading the PLC once more, waiting up to {wait:.0f} s for its "
                       "next Ready to count it as missed (Ctrl-C skips this)")
    progress(result)
    reading = asyncio.create_task(_read_after(target, result, last_handshakes, wait))
    stopping = asyncio.create_task(stop.wait())
    try:
        await asyncio.wait({reading, stopping}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        stopping.cancel()
        if not reading.done():
            reading.cancel()
            await asyncio.gather(reading, return_exceptions=True)
            result.errors.append("interrupted by the user while waiting for the PLC's next Ready (not counted)")
        result.activity = ""


async def _read_after(target: Target, result: Measurement, last_handshakes: int | None, wait: float) -> None:
    from softplc.latency.client import build_driver, build_parser

    argv = client_command(target, result.endpoint)[3:]
    try:
        args = build_parser().parse_args(argv)
        args.mode = "poll"  # one read at a time is all this needs
        args.password = target.password
        driver = build_driver(args)
        await driver.connect()
    except Exception as error:
        result.errors.append(f"cannot read the PLC after the client died: {error}")
        return
    try:
        # The PLC may be in the middle of a task: wait for it to ask for the next one.
        deadline = time.monotonic() + wait
        snapshot = await driver.read()
        while not snapshot.ready and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
            snapshot = await driver.read()
        if snapshot.ready:
            result.missed += 1
            result.missed_notes.append(_unanswered_note(result, snapshot.ready_stamp))
        if snapshot.handshakes is not None and last_handshakes is not None:
            result.unreported += max(0, snapshot.handshakes - last_handshakes)
    except Exception as error:
        result.errors.append(f"cannot read the PLC after the client died: {error}")
    finally:
        await driver.close()


def _unanswered_note(result: Measurement, ready_stamp: float | None) -> str:
    """When the Ready left unanswered was set, relative to the client's end."""
    gone = result.client_gone_at
    if ready_stamp is None or gone is None or not result.same_clock:
        return "a Ready found set after the client ended, never answered"
    after = ready_stamp - gone
    if after >= 0:
        return f"a Ready the PLC set {after:.1f} s after the client ended, never answered"
    return f"a Ready pending since {-after:.1f} s before the client ended, never answered"


def client_command(target: Target, endpoint: str) -> list[str]:
    """argv of the client process."""
    argv = [sys.executable, "-m", "softplc.latency.client", "--protocol", target.protocol, "--endpoint", endpoint,
            "--mode", target.mode, "--timeout", f"{target.ready_timeout():g}",
            "--poll-interval", f"{target.poll_interval_ms:g}", "--publishing-interval", f"{target.publishing_interval_ms:g}",
            "--unit-id", str(target.unit_id), "--word-order", target.word_order]
    if target.samples is not None:
        argv += ["--samples", str(target.samples)]
    if target.duration is not None:
        argv += ["--duration", f"{target.duration:g}"]
    for tag in target.tags:
        argv += ["--tag", tag]
    if target.client_cpus is not None:
        argv += ["--cpus", format_cpus(target.client_cpus)]
    for option, value in (("--namespace", target.namespace), ("--security", target.security), ("--user", target.user)):
        if value:
            argv += [option, value]
    return argv
