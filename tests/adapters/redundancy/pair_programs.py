"""A program that drives an output device stamped with the epoch (the checker of the redundancy fault tests and bench)."""

from __future__ import annotations

import os
import socket
import time

from softplc import Input, Param, Program

_SOCKETS: dict[int, socket.socket] = {}  # not the program's state: a socket cannot travel to the standby


class EpochOutput(Program):
    """Sends one UDP datagram per scan to a device on this machine: process id, epoch, scans, monotonic time."""

    scans = Input("the plant's scan counter")
    port = Param(0, "the device's UDP port on 127.0.0.1 (0: none)")

    def scan(self) -> None:
        if not self.port:
            return
        sender = _SOCKETS.get(self.port)
        if sender is None:
            sender = _SOCKETS[self.port] = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        message = f"{os.getpid()} {self.epoch} {self.scans} {time.monotonic():.6f}".encode()
        if not self.driving:
            return  # frozen in this scan and woken past its term: the standby drives now
        try:
            sender.sendto(message, ("127.0.0.1", self.port))
        except OSError:
            pass  # the device is gone: the plant scans on
