"""What one latency measurement measures: protocol, scenario, PLC scan, client mode and limits."""

from __future__ import annotations

from dataclasses import dataclass, field

from softplc.latency.plant import scenario_durations


@dataclass
class Target:
    """What to measure and how (the `softplc latency` options of one protocol × scenario)."""

    protocol: str  # opcua | modbus
    scenario: str  # slow | average | fast
    scan: float = 0.01  # the PLC's scan in s (ours; for --endpoint, what the remote PLC runs)
    client_mode: str | None = None  # subscription | poll | link; None: subscription for OPC UA, poll for Modbus
    endpoint: str | None = None  # None: start our runtime
    samples: int | None = None
    duration: float | None = None
    tags: list[str] = field(default_factory=list)  # ROLE=ADDRESS overrides for --endpoint
    namespace: str | None = None
    security: str | None = None
    user: str | None = None
    password: str | None = None
    unit_id: int = 1
    word_order: str = "big"
    poll_interval_ms: float = 1.0
    publishing_interval_ms: float = 0.0
    timeout: float | None = None  # per Ready; default: the longest task + 1 s
    loop: str = "asyncio"
    client_cpus: frozenset[int] | None = None  # CPUs the client process is kept on (None: the OS places it)

    @property
    def mode(self) -> str:
        return self.client_mode or ("subscription" if self.protocol == "opcua" else "poll")

    @property
    def label(self) -> str:
        return f"{self.protocol} {self.scenario}"

    def ready_timeout(self) -> float:
        if self.timeout is not None:
            return self.timeout
        return max(scenario_durations(self.scenario)) + 1.0 + 3 * self.scan
