"""CPU lists for `--cpus` (softplc run, softplc latency and its client): read as taskset reads them."""

from __future__ import annotations

import argparse
import os

import pytest

from softplc.util.realtime import RealtimeError, check_cpus, cpu_list, format_cpus, parse_cpus


@pytest.mark.parametrize("text, cpus", [("0", {0}), ("0,2", {0, 2}), ("1-3", {1, 2, 3}), (" 0 , 4-5 ", {0, 4, 5}), ("2,2", {2})])
def test_lists_are_read_as_taskset_reads_them(text: str, cpus: set[int]) -> None:
    assert parse_cpus(text) == cpus


@pytest.mark.parametrize("cpus, text", [({0}, "0"), ({0, 1, 2, 3, 6}, "0-3,6"), ({1, 3, 5}, "1,3,5"), ({4, 5}, "4-5")])
def test_sets_are_written_back_in_the_same_syntax(cpus: set[int], text: str) -> None:
    assert format_cpus(frozenset(cpus)) == text
    assert parse_cpus(text) == cpus


@pytest.mark.parametrize("text, message", [
    ("", "'' is not a CPU list"),
    ("a", "'a' is not a CPU list: write CPU numbers and ranges, e.g. 0 or 0,2 or 1-3"),
    ("-1", "'-1' is not a CPU list"),
    ("1-", "'1-' is not a CPU list"),
    ("1,,2", "'1,,2' is not a CPU list"),
    ("3-1", "'3-1': a range goes from the lower CPU number to the higher one"),
])
def test_a_malformed_list_says_what_is_wrong(text: str, message: str) -> None:
    with pytest.raises(ValueError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        parse_cpus(text)
    with pytest.raises(argparse.ArgumentTypeError, match=message.split(":")[0].replace("(", r"\(")):
        cpu_list(text)


def test_a_cpu_the_machine_lacks_is_refused_with_the_ones_it_has() -> None:
    count = os.cpu_count() or 1
    check_cpus(frozenset(range(count)))  # every CPU it has: fine
    with pytest.raises(RealtimeError, match=f"^there is no CPU {count}, {count + 5}: this machine has CPU "):
        check_cpus(frozenset({0, count, count + 5}))
