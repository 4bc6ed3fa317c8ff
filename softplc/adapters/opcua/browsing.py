"""Browse continuation points: RequestedMaxReferencesPerNode and BrowseNext (OPC UA Part 4, 5.8).

asyncua 2.1.0 returns every reference of a node whatever the client asked for, and has no
BrowseNext. `GuardedProcessor` (transport.py) passes each Browse result through
`ContinuationPoints.page`, which keeps the first RequestedMaxReferencesPerNode references and
holds back the rest under a random continuation point; BrowseNext hands them out page by
page, or releases them. Points belong to the session (at most `MAX_CONTINUATION_POINTS`; a
further one is refused with BadNoContinuationPoints) and die with it.

`SubtypeCachingViewService` answers Browse like asyncua's ViewService, but remembers whether
one reference type is a subtype of another: asyncua walks the whole subtype tree for every
reference of every browsed node (~40 µs a reference; 1,000 alarm conditions held the loop
0.15-0.4 s per browsed level), the cache ~2 µs.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass

from asyncua import ua
from asyncua.server.address_space import AddressSpace, ViewService

MAX_CONTINUATION_POINTS = 10  # per session; advertised as ServerCapabilities.MaxBrowseContinuationPoints


@dataclass
class _Held:
    references: list[ua.ReferenceDescription]
    page_size: int


class ContinuationPoints:
    """The references held back for one session's BrowseNext."""

    def __init__(self, most: int = MAX_CONTINUATION_POINTS) -> None:
        self.most = most
        self._held: dict[bytes, _Held] = {}

    def page(self, results: list[ua.BrowseResult], page_size: int) -> None:
        """Cut each result to `page_size` references (0: no limit), holding back the rest."""
        if page_size <= 0:
            return
        for result in results:
            if len(result.References) > page_size:
                self._cut(result, result.References, page_size)

    def next(self, points: list[bytes], release: bool) -> list[ua.BrowseResult]:
        """BrowseNext: the next page for each point, or (release) forget them."""
        results = []
        for point in points:
            held = self._held.pop(point, None) if point else None
            if held is None:
                results.append(ua.BrowseResult(StatusCode=ua.StatusCode(ua.StatusCodes.BadContinuationPointInvalid)))
            elif release:
                results.append(ua.BrowseResult())
            else:
                result = ua.BrowseResult()
                self._cut(result, held.references, held.page_size)
                results.append(result)
        return results

    def _cut(self, result: ua.BrowseResult, references: list[ua.ReferenceDescription], page_size: int) -> None:
        result.References = references[:page_size]
        rest = references[page_size:]
        if not rest:
            return
        if len(self._held) >= self.most:
            result.References = []
            result.StatusCode = ua.StatusCode(ua.StatusCodes.BadNoContinuationPoints)
            return
        point = secrets.token_bytes(16)
        self._held[point] = _Held(rest, page_size)
        result.ContinuationPoint = point


class SubtypeCachingViewService(ViewService):
    """asyncua's Browse, with "is reference type B a subtype of A" remembered (the types never change once served)."""

    def __init__(self, aspace: AddressSpace) -> None:
        super().__init__(aspace)
        self._suitable: dict[tuple[ua.NodeId, ua.NodeId, bool], bool] = {}

    def _suitable_reftype(self, ref1: ua.NodeId, ref2: ua.NodeId, subtypes: bool) -> bool:
        key = (ref1, ref2, subtypes)
        suitable = self._suitable.get(key)
        if suitable is None:
            # Bounded: keys are pairs of reference types (a few dozen), whatever the clients ask.
            suitable = self._suitable[key] = super()._suitable_reftype(ref1, ref2, subtypes)
        return suitable
