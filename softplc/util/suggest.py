"""'Did you mean' hints for names a user mistyped (tags, keys, programs, scenarios)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def closest(word: str, choices: Iterable[str]) -> str | None:
    """The choice `word` most likely meant: a different case first (t01_qsl → t01_qSL), else the closest spelling."""
    options = list(choices)
    folded = [choice for choice in options if choice.casefold() == word.casefold()]
    if folded:
        return folded[0]
    close = difflib.get_close_matches(word, options, n=1, cutoff=0.6)
    return close[0] if close else None


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """' (did you mean 'x'?)' when a choice is close to `word`, else ''."""
    match = closest(word, choices)
    return f" (did you mean '{match}'?)" if match is not None else ""
