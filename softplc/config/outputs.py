"""Tags written by more than one program: the double-coil bug, unless the tag says `shared_output: true`.

Within a task the program that runs last overrides what the others decided; across tasks the
tag flips between the programs' values. Either way one program's decision is silently lost, so
a second writer is a configuration problem. Handshakes (one program sets a flag, another clears
it) and counters every program increments are meant to be shared: the tag says so. A disabled
program writes nothing and does not count.
"""

from __future__ import annotations

from softplc.config.findings import Findings
from softplc.config.programs import Write


def check_outputs(findings: Findings, writes: list[Write], shared: set[str]) -> None:
    """One problem per tag written by two or more programs, at the second one's binding."""
    writers: dict[str, dict[str, Write]] = {}  # tag → program → its first binding of the tag
    for write in writes:
        writers.setdefault(write.tag, {}).setdefault(write.program, write)
    for tag, by_program in writers.items():
        if len(by_program) < 2 or tag in shared:
            continue
        found = list(by_program.values())
        here = findings.source.value(found[1].path)
        described = []
        for write in found:
            location = findings.source.value(write.path)
            described.append(f"'{write.program}' (its output '{write.variable}'" + ("" if location == here else f", at {location}") + ")")
        listed = ", ".join(described[:-1]) + " and " + described[-1]
        # Found for a `for_each` instance: said once for all the instances with the same mistake.
        findings.problem(found[1].path, f"'{tag}' is written by {len(found)} programs, {listed}: the one that runs last "
                         "overrides the others (the double-coil bug); let one program write it, or declare the tag with "
                         "shared_output: true if they take turns on purpose", instance=found[1].instance)
