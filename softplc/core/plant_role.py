"""The plant's role in a redundant pair: ACTIVE, STANDBY or FENCED, and the term an ACTIVE role lasts.

A runtime alone is ACTIVE for ever. In a redundant pair an adapter (softplc/adapters/redundancy/)
decides the role and sets it here; the core honours it without knowing how it was decided:

- **ACTIVE** scans its programs, drives its outputs and accepts writes — but only until `until`
  (a time of the plant's clock): an active whose term lapses behaves as FENCED at once, even if
  nothing has told it yet. That is what makes a frozen process safe when it wakes up: its first
  scan, write or output asks `is_active()` before anything else runs.
- **STANDBY** mirrors the active: no scan, no outputs; writes are refused with rule NOT_ACTIVE
  and a detail naming the active.
- **FENCED** was active and may have lost its term: like STANDBY, until told otherwise.

`epoch` grows with every new ACTIVE term of the pair (a fencing token): everything an active
sends out carries it, so a receiver can ignore an older active.
"""

from __future__ import annotations

import enum
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

log = logging.getLogger(__name__)


class PlantRole(enum.Enum):
    ACTIVE = "ACTIVE"
    STANDBY = "STANDBY"
    FENCED = "FENCED"


@dataclass(frozen=True)
class RoleTerm:
    """A role and how long it holds: the epoch, the end of an ACTIVE term, and what refused writers are told."""

    role: PlantRole = PlantRole.ACTIVE
    epoch: int = 0
    until: float = math.inf  # clock time after which an ACTIVE term has lapsed
    active: str = ""  # who is active now (name and address), '' when unknown
    detail: str = ""  # why writes are refused here: "this runtime (b) is the standby; write to the active, a (...)"


RoleCallback = Callable[[RoleTerm], None]


class RoleHolder:
    """The plant's current role term, asked by the engine before each cycle and by the tag database at each write."""

    def __init__(self, now: Callable[[], float]) -> None:
        self._now = now
        self.term = RoleTerm()
        self.member = ""  # this runtime's name in a redundant pair ('' alone), set before any adapter starts
        self._callbacks: list[RoleCallback] = []
        self._lapsed_told = False
        self._lock = threading.Lock()  # `renew` may come from another thread (a lease keeper)

    @property
    def role(self) -> PlantRole:
        """The role as it holds now: an ACTIVE term past its end counts as FENCED."""
        term = self.term
        if term.role is PlantRole.ACTIVE and self._now() >= term.until:
            return PlantRole.FENCED
        return term.role

    @property
    def epoch(self) -> int:
        return self.term.epoch

    def is_active(self) -> bool:
        """Whether this plant may scan, drive outputs and accept writes right now."""
        term = self.term
        if term.role is not PlantRole.ACTIVE:
            return False
        if self._now() < term.until:
            return True
        if not self._lapsed_told:
            self._lapsed_told = True
            log.warning("the active term (epoch %d) lapsed before it was renewed: fenced (no scan, no outputs, no writes)", term.epoch)
        return False

    def refusal(self) -> str:
        """Why a client write is refused here ('' while active)."""
        if self.is_active():
            return ""
        term = self.term
        if term.role is PlantRole.ACTIVE:
            return f"this runtime's active term (epoch {term.epoch}) has lapsed: it is fenced until its coordinator confirms it"
        return term.detail or f"this runtime is {term.role.value.lower()}: it does not accept writes"

    def set(self, term: RoleTerm) -> None:
        """Take a new term (role, epoch, end); listeners hear of a change of role or epoch."""
        with self._lock:
            previous = self.term
            self.term = term
            self._lapsed_told = False
        if (previous.role, previous.epoch, previous.active) == (term.role, term.epoch, term.active):
            return
        for callback in list(self._callbacks):
            try:
                callback(term)
            except Exception:  # a broken listener must not keep the role from changing
                log.exception("role listener %r failed", callback)

    def renew(self, until: float, epoch: int | None = None) -> None:
        """Extend the ACTIVE term (of `epoch`, if given) to `until` (a renewed lease): no listener is told.

        Safe from another thread: a term set meanwhile (fenced, stopping) is never revived.
        """
        with self._lock:
            term = self.term
            if term.role is PlantRole.ACTIVE and until > term.until and (epoch is None or term.epoch == epoch):
                self.term = RoleTerm(term.role, term.epoch, until, term.active, term.detail)

    def own(self, name: str) -> str:
        """`name`, made this runtime's own in a pair (`name-MEMBER`): e.g. a client id both members use at once."""
        return f"{name}-{self.member}" if self.member else name

    def on_change(self, callback: RoleCallback) -> Callable[[], None]:
        """Call `callback(term)` whenever the role, the epoch or the active changes; returns an undo."""
        self._callbacks.append(callback)
        return lambda: self._callbacks.remove(callback) if callback in self._callbacks else None
