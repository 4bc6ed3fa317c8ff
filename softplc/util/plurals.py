"""Counts in messages: "1 write", "2 writes" — never "1 writes"."""

from __future__ import annotations


def plural(count: int, noun: str, many: str | None = None) -> str:
    """`count` and `noun`, the noun in the plural unless the count is one ('1 item', '3 items', '0 items').

    `noun` may be a phrase whose last word is the noun ('more connection'); `many` is the plural
    when adding an s is wrong ('entry', 'entries').
    """
    return f"{count} {noun if count == 1 else many or noun + 's'}"


def counted(count: int, phrase: str) -> str:
    """`count` and a plural `phrase` whose first word ending in s is the noun, made singular for one.

    For phrases kept in the plural as keys (a flood's kind): counted(1, "failed logins") is
    '1 failed login', counted(1, "connections closed for bad requests") '1 connection closed for bad requests'.
    """
    if count != 1:
        return f"{count} {phrase}"
    words = phrase.split(" ")
    for index, word in enumerate(words):
        if word.endswith("s") and not word.endswith("ss"):
            words[index] = word[:-1]
            break
    return f"1 {' '.join(words)}"
