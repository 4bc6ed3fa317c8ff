"""The client side of the case IV handshake as a scan program: another PLC answers the handshake PLC through a link.

Thesis case study IV had a Python OPC client answer the PLC; here a second softplc runtime does,
PLC to PLC: its `Ready` is bound both ways to the handshake PLC's Ready, its `TaskID` out to the
PLC's TaskID (programs/handshake_answer.yaml, the `links:` section; docs/latency.md). When a
scan sees Ready, it assigns the next task (1 → 2 → 3 → 1) and clears Ready: the link sends
both to the PLC in one request at the end of the scan.

`SeenStamp` (bound out to the PLC's AnswerSeen) is the system-wide monotonic time at which this
program saw Ready: with the PLC's ReadyStamp it splits the delay into Ready→seen (the link's
delivery and this runtime's scan) and seen→taken (this scan's outputs over the link).
"""

from __future__ import annotations

from softplc import InOut, Output, Program

TASK_IDS = (1, 2, 3)


class HandshakeAnswer(Program):
    ready = InOut("the PLC's Ready: set by the PLC, cleared here when answered (bound both ways)")
    task_id = Output("the next task for the PLC: 1 → 2 → 3 → 1 (bound out to its TaskID)")
    seen_stamp = Output("system monotonic time in s this program saw Ready (bound out to the PLC's AnswerSeen)", optional=True)
    answers = Output("Readys answered since start", optional=True)

    def setup(self) -> None:
        self.next_task = TASK_IDS[0]
        self.count = 0

    def scan(self) -> None:
        if not self.ready:
            return
        self.seen_stamp = self.clock.monotonic()
        self.task_id = self.next_task
        self.next_task = self.next_task % len(TASK_IDS) + 1
        self.ready = False
        self.count += 1
        self.answers = self.count
