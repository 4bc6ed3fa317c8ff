"""Handshake task switching, thesis case study IV: the PLC side of the latency measurement.

Three tasks with fixed durations run one at a time on PLC timers. When the running task's
time has elapsed the PLC sets Ready; a client (any OPC UA or Modbus program) answers by
writing the next TaskID (1 → 2 → 3 → 1) and clearing Ready. A fourth timer measures the delay
from setting Ready to seeing the new TaskID; it is quantised to the scan, as in the thesis.

Scenarios (task 1 / 2 / 3 durations): slow 10/20/30 s, average 1/2/5 s, fast 100/200/500 ms.

Besides the thesis's Ready / TaskID / Delay this publishes what lets a report separate
protocol latency from scan quantisation: DelayScans (the delay in whole scans), Handshakes
(a counter of completed task switches, so a client can tell a missed handshake) and
ReadyStamp (the system-wide monotonic time at which Ready was set, in seconds).

The first assignment after start (TaskID 0 → a task) is the start of the sequence, not a
task switch: it is neither timed nor counted.
"""

from __future__ import annotations

from softplc import TON, InOut, Input, Output, Param, Program

# Task durations in seconds, per scenario (thesis §5.4.3).
SCENARIOS: dict[str, tuple[float, float, float]] = {
    "slow": (10.0, 20.0, 30.0),
    "average": (1.0, 2.0, 5.0),
    "fast": (0.1, 0.2, 0.5),
}

TASK_IDS = (1, 2, 3)

# The delay timer's preset: a TON stops counting at PT, and a handshake must never look
# shorter than it was, so PT is effectively infinite (a year).
_NEVER = 365 * 24 * 3600.0


class Handshake(Program):
    scenarios = SCENARIOS  # read by `softplc latency` to know how long to wait for a Ready

    ready = InOut("set by the PLC when the running task is done; the client clears it (Ready)")
    task_id = Input("task assigned by the client: 1, 2 or 3 (TaskID)")
    delay = Output("delay from setting Ready to seeing the new TaskID in ms, scan-quantised (Delay)")
    delay_scans = Output("the same delay in scans (DelayScans)", optional=True)
    handshakes = Output("completed task switches since start (Handshakes)", optional=True)
    ready_stamp = Output("system monotonic time in s at which Ready was last set (ReadyStamp)", optional=True)
    running_task = Output("the task running now; 0 while waiting for the client (RunningTask)", optional=True)

    scenario = Param("fast", "task durations: slow (10/20/30 s), average (1/2/5 s) or fast (100/200/500 ms)")
    scan_interval = Param(0.01, "the interval of the task this program runs in; Delay = DelayScans × it", duration=True)

    def setup(self) -> None:
        if self.scenario not in SCENARIOS:
            raise ValueError(f"unknown scenario {self.scenario!r}; expected one of: {', '.join(SCENARIOS)}")
        if self.scan_interval <= 0:
            raise ValueError("scan_interval must be positive")
        self.durations = SCENARIOS[self.scenario]
        self.task_timers = [TON(self.clock) for _ in TASK_IDS]
        self.delay_timer = TON(self.clock)
        self.active = 0  # the task the PLC is running or has just finished
        self.waiting = False  # Ready has been set and no new TaskID seen yet
        self.count = 0
        self.scans_waited = 0  # scans run since the one that set Ready

    def scan(self) -> None:
        # The delay timer runs from the scan that sets Ready; update it first so it reads the
        # time of this scan, as a PLC timer called at the top of the program would.
        self.delay_timer(IN=self.waiting, PT=_NEVER)
        if self.waiting:
            self.scans_waited += 1

        if self.task_id in TASK_IDS and self.task_id != self.active:
            if self.waiting and self.active != 0:
                # In scans: the timer's time rounded to the scan, but never fewer than the scans
                # that actually ran (a late start of the setting scan shortens the timer's view).
                scans = max(self.scans_waited, round(self.delay_timer.ET / self.scan_interval))
                self.delay_scans = scans
                self.delay = scans * self.scan_interval * 1000.0
                self.count += 1
                self.handshakes = self.count
            self.active = self.task_id
            self.waiting = False
            self.ready = False  # acknowledged; the client clears it too, which is harmless
            self.delay_timer(IN=False)

        for task, timer in zip(TASK_IDS, self.task_timers):
            timer(IN=self.active == task and not self.waiting, PT=self.durations[task - 1])

        # At start (no task yet) the PLC asks for the first one at once.
        done = self.active == 0 or self.task_timers[self.active - 1].Q
        if done and not self.waiting:
            self.waiting = True
            self.ready = True
            self.ready_stamp = self.clock.monotonic()
            self.delay_timer(IN=True, PT=_NEVER)
            self.scans_waited = 0
        self.running_task = 0 if self.waiting else self.active
