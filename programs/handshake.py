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

Clients that break the handshake are counted, never left to stall it:
- a TaskID written while a task runs (no Ready to answer) is followed at once, cutting that
  task short, but is no handshake: it is counted in Unexpected and not timed;
- Ready cleared without a valid new TaskID (the same one, or 0): the PLC waits one more scan
  (a client may clear Ready and write TaskID in two requests), then sets Ready again and counts
  it in BadAnswers. The delay keeps running from the first Ready.
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
    unexpected = Output("TaskIDs written while a task was running, followed but not timed (Unexpected)", optional=True)
    bad_answers = Output("times Ready was cleared without a valid new TaskID and set again (BadAnswers)", optional=True)

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
        self.unexpected_count = 0
        self.bad_answer_count = 0
        self.scans_waited = 0  # scans run since the one that set Ready
        self.cleared_without_task = False  # Ready was found cleared with no new TaskID last scan

    def scan(self) -> None:
        # The delay timer runs from the scan that sets Ready; update it first so it reads the
        # time of this scan, as a PLC timer called at the top of the program would.
        self.delay_timer(IN=self.waiting, PT=_NEVER)
        if self.waiting:
            self.scans_waited += 1

        new_task = self.task_id in TASK_IDS and self.task_id != self.active
        if new_task and self.waiting:
            if self.active != 0:  # the first assignment starts the sequence: not timed
                # In scans: the timer's time rounded to the scan, but never fewer than the scans
                # that actually ran (a late start of the setting scan shortens the timer's view).
                scans = max(self.scans_waited, round(self.delay_timer.ET / self.scan_interval))
                self.delay_scans = scans
                self.delay = scans * self.scan_interval * 1000.0
                self.count += 1
                self.handshakes = self.count
            self.start_task(self.task_id)
        elif new_task:
            # No Ready to answer: the PLC follows its TaskID, but this is no handshake.
            self.unexpected_count += 1
            self.unexpected = self.unexpected_count
            self.start_task(self.task_id)
        elif self.waiting and not self.ready:
            # Cleared without a valid new TaskID: give it one scan to arrive, then ask again.
            if self.cleared_without_task:
                self.ready = True
                self.bad_answer_count += 1
                self.bad_answers = self.bad_answer_count
            self.cleared_without_task = not self.cleared_without_task

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

    def start_task(self, task: int) -> None:
        """Run `task` from now on; Ready is acknowledged (the client clears it too, which is harmless)."""
        self.active = task
        self.waiting = False
        self.ready = False
        self.delay_timer(IN=False)
        self.cleared_without_task = False
