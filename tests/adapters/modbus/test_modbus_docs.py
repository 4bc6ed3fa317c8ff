"""The Modbus examples of docs/modbus.md and the README are true for the default plant.

Each mbpoll command is checked against the default plant's address map (`softplc modbus-map`):
every value it reads or writes starts exactly at a tag of the type and word order the command
asks for, and the tags named in its comment are those it covers. Then the commands, and the
pymodbus example, run against a freshly started default plant (`softplc run` on a free port)
and must print what their comments say.
"""

from __future__ import annotations

import json
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from conftest import REPO
from modbus_helpers import mbpoll_path, polled

from softplc.adapters.modbus.address_map import Table, build_address_map
from softplc.config import load_config

DOCS = [REPO / "docs" / "modbus.md", REPO / "README.md"]
TABLES = {"0": "coil", "1": "discrete_input", "3": "input", "4": "holding"}
# mbpoll's element types: words per value and the encodings they can read.
ELEMENTS = {"": (1, {"uint16", "int16", "bool", "bit"}), "hex": (1, {"uint16", "int16", "bool", "bit"}),
            "int": (2, {"int32", "uint32"}), "float": (2, {"float32"})}


@dataclass
class Example:
    """One documented mbpoll command, parsed."""

    where: str  # file:line
    line: str
    table: str
    element: str
    address: int  # 0-based
    count: int
    big: bool
    writes: list[str]
    comment: str
    options: list[str] = field(default_factory=list)  # the command's arguments after "mbpoll"
    read_options: list[str] = field(default_factory=list)  # the same without the values written

    @property
    def words(self) -> int:
        return ELEMENTS[self.element][0]

    @property
    def starts(self) -> list[int]:
        return [self.address + index * self.words for index in range(self.count)]

    @property
    def number(self) -> int:
        """The first reference mbpoll prints ([N]: value)."""
        return int(self.options[self.options.index("-r") + 1])

    @property
    def expected(self) -> list[str]:
        """The values the comment promises ('...: 100 0 100'), if any."""
        match = re.search(r":\s*(-?[\d.]+(?:\s+-?[\d.]+)*)\s*$", self.comment)
        return match.group(1).split() if match else []

    @property
    def illegal(self) -> bool:
        return "Illegal data address" in self.comment


def parse(where: str, text: str) -> Example:
    command, _, comment = text.partition("#")
    words = shlex.split(command)
    assert words[0] == "mbpoll", where
    options = words[1:]
    table, element, first, count, zero_based, big, positional = "4", "", 1, 1, False, False, []
    written: set[int] = set()  # indices of the values to write
    index = 0
    while index < len(options):
        option = options[index]
        if option in ("-m", "-a", "-p", "-o", "-l"):
            index += 1
        elif option == "-t":
            index += 1
            table, _, element = options[index].partition(":")
        elif option == "-r":
            index += 1
            first = int(options[index])
        elif option == "-c":
            index += 1
            count = int(options[index])
        elif option == "-0":
            zero_based = True
        elif option == "-B":
            big = True
        elif option in ("-1", "--"):
            pass
        else:
            assert not option.startswith("-") or re.fullmatch(r"-[\d.]+", option), f"{where}: option {option} unknown to this test"
            positional.append(option)
            if len(positional) > 1:
                written.add(index)
        index += 1
    assert positional and positional[0] == "127.0.0.1", f"{where}: the host must be 127.0.0.1"
    assert "-p" in options and options[options.index("-p") + 1] == "5020", f"{where}: examples use the default port 5020"
    read_options = [option for index, option in enumerate(options) if index not in written and option != "--"]
    return Example(where, text, TABLES[table], element, first if zero_based else first - 1, count, big, positional[1:],
                   comment.strip(), options, read_options)


def documented_examples() -> list[Example]:
    """Every mbpoll command in the docs: one per line of a code block, or in inline code."""
    examples = []
    for path in DOCS:
        in_code = False
        for number, line in enumerate(path.read_text().splitlines(), 1):
            where = f"{path.relative_to(REPO)}:{number}"
            if line.startswith("```"):
                in_code = not in_code
            elif in_code and line.startswith("mbpoll "):
                examples.append(parse(where, line))
            elif not in_code:
                examples += [parse(where, inline) for inline in re.findall(r"`(mbpoll [^`]+)`", line)]
    return examples


EXAMPLES = documented_examples()


@pytest.fixture(scope="module")
def address_map() -> dict:
    """`softplc modbus-map --format json` of the default plant, as users see it."""
    done = subprocess.run([sys.executable, "-m", "softplc.app.cli", "modbus-map", "--format", "json"], cwd=str(REPO),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_docs_have_mbpoll_examples():
    assert len([e for e in EXAMPLES if e.where.startswith("docs/")]) >= 8
    assert any(e.where.startswith("README") for e in EXAMPLES)


@pytest.mark.parametrize("example", EXAMPLES, ids=[e.where for e in EXAMPLES])
def test_an_mbpoll_example_lands_on_the_tags_it_names(example, address_map):
    tags = [tag for tag in address_map["tags"] if tag["table"] == example.table]
    named = [word for word in re.findall(r"[\w.]+", example.comment) if word in {tag["tag"] for tag in address_map["tags"]}]
    if example.illegal:
        assert not any(tag["address"] <= example.address < tag["address"] + tag["words"] for tag in tags), example.line
        return
    covered = []
    for start in example.starts:
        at = [tag for tag in tags if tag["address"] == start]
        assert at, f"{example.where}: no {example.table} tag starts at address {start}: {example.line}"
        tag = at[0]
        words, encodings = ELEMENTS[example.element]
        assert tag["encoding"] in encodings and tag["words"] == words, \
            f"{example.where}: {tag['tag']} is {tag['encoding']} in {tag['words']} words, mbpoll reads it as {example.element or '16-bit'}"
        if words == 2:
            assert (tag["word_order"] == "big") == example.big, f"{example.where}: {tag['tag']} word order {tag['word_order']}, -B {example.big}"
        covered.append(tag["tag"])
    if named or example.where.startswith("docs/"):
        assert named == covered, f"{example.where}: the comment names {named}, the command covers {covered}"
    for start, tag_name in zip(example.starts, covered):
        tag = next(tag for tag in tags if tag["tag"] == tag_name)
        assert not example.writes or tag["access"] == "rw", f"{example.where}: writes the read-only {tag_name}"
    if example.expected:
        assert len(example.expected) == example.count, f"{example.where}: {example.count} values, {len(example.expected)} promised"


def test_the_map_excerpt_in_the_docs_is_the_real_map(address_map):
    text = (REPO / "docs" / "modbus.md").read_text()
    excerpt = text.split("$ softplc modbus-map", 1)[1].split("```", 1)[0].splitlines()[1:]
    assert excerpt[0].split() == ["Modbus", "TCP", "127.0.0.1:5020", "unit", "1,", "word", "order", "big"]
    columns = excerpt[1].split()
    rows = {tag["tag"]: tag for tag in address_map["tags"]}
    checked = 0
    for line in excerpt[2:]:
        if line.strip() in ("", "..."):
            continue
        cells = line.split()
        tag = rows[cells[0]]
        real = [str(tag[column]) if tag[column] not in (None, "") else "" for column in columns]
        assert cells == [cell for cell in real if cell], f"docs: {line}\nmap:  {real}"
        checked += 1
    assert checked >= 4


class Plant:
    """`softplc run` of the default plant on a free Modbus port, without OPC UA."""

    def __init__(self, process: subprocess.Popen[str], port: int, serving: str) -> None:
        self.process, self.port, self.serving = process, port, serving

    def mbpoll(self, example: Example, *, read: bool = False) -> tuple[int, str]:
        """Run the example on this plant's port (`read`: the same command without its values)."""
        options = list(example.read_options if read else example.options)
        options[options.index("-p") + 1] = str(self.port)
        done = subprocess.run([mbpoll_path(), "-o", "2", *options], capture_output=True, text=True, timeout=15)
        return done.returncode, done.stdout + done.stderr


@pytest.fixture(scope="module")
def default_plant(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Plant]:
    folder: Path = tmp_path_factory.mktemp("docs")
    process = subprocess.Popen(
        [sys.executable, "-m", "softplc.app.cli", "run", "--modbus-port", "0", "--no-opcua", "--no-status",
         "--state-dir", str(folder / "state")],
        cwd=str(REPO), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    watchdog = threading.Timer(60, process.kill)  # a hung start fails the test instead of hanging it
    watchdog.start()
    lines: list[str] = []
    assert process.stderr is not None
    try:
        while True:
            line = process.stderr.readline()
            if not line:
                raise AssertionError("softplc run exited before serving:\n" + "".join(lines))
            lines.append(line)
            if match := re.search(r"serving: Modbus TCP on 127\.0\.0\.1:(\d+) unit 1 .*", line):
                break
    finally:
        watchdog.cancel()
    yield Plant(process, int(match.group(1)), match.group(0))
    process.send_signal(signal.SIGINT)
    try:
        process.wait(15)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(10)


def test_the_documented_serving_line_matches(default_plant):
    documented = re.search(r"`serving: Modbus TCP on 127\.0\.0\.1:5020 unit 1 \((\d+) tags: \.\.\.\)`",
                           (REPO / "docs" / "modbus.md").read_text())
    assert documented, "docs/modbus.md no longer quotes the serving line"
    assert f"({documented.group(1)} tags: " in default_plant.serving, default_plant.serving


@pytest.mark.parametrize("example", EXAMPLES, ids=[e.where for e in EXAMPLES])
def test_an_mbpoll_example_prints_what_its_comment_says(example, default_plant):
    code, out = default_plant.mbpoll(example)
    if example.illegal:
        assert code != 0 and "Illegal data address" in out, out
        return
    assert code == 0, out
    if example.writes:
        assert f"Written {len(example.writes)} references" in out, out
        if example.comment.startswith("write") and "_sys." not in example.comment:  # commands reset themselves
            deadline = time.monotonic() + 5  # applied at the next cycle boundary
            while list(polled(default_plant.mbpoll(example, read=True)[1]).values()) != example.writes:
                assert time.monotonic() < deadline, f"{example.where}: {example.writes} not read back"
                time.sleep(0.05)
        return
    values = polled(out)
    numbers = [example.number + index * example.words for index in range(example.count)]
    assert list(values) == numbers, out
    for value in values.values():
        float(value) if example.element == "float" else int(value, 16 if example.element == "hex" else 10)
    if example.expected:
        assert [float(value) for value in values.values()] == [float(value) for value in example.expected], out


def test_the_pymodbus_example_runs(default_plant, tmp_path):
    text = (REPO / "docs" / "modbus.md").read_text()
    code = text.split("pymodbus:\n\n```python\n", 1)[1].split("```", 1)[0]
    assert "port=5020" in code
    script = tmp_path / "example.py"
    script.write_text(code.replace("port=5020", f"port={default_plant.port}"))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    match = re.fullmatch(r"r01_xgoal = (\S+)\n", done.stdout)
    assert match and 0.0 <= float(match.group(1)) <= 21.95, done.stdout + done.stderr


def test_the_per_tag_overrides_example_maps_as_its_comments_say(tmp_path):
    text = (REPO / "docs" / "modbus.md").read_text()
    block = text.split("### Per-tag overrides\n\n```yaml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "tagdb.yaml").write_text(f"version: 1\n{block}tasks:\n  fast: {{interval: 100ms}}\nservers:\n  modbus: {{}}\n")
    mapping = build_address_map(load_config(tmp_path / "tagdb.yaml")).by_tag
    assert mapping["t01_level"].codec.encode(12.34) == [1234] and mapping["t01_level"].words == 1  # "12.34 % ↔ 1234 in an int16"
    assert mapping["total_mass"].words == 2 and mapping["total_mass"].codec.encode(1.2) == [0, 12]  # "0.1 kg resolution, 2 registers"
    assert (mapping["heartbeat"].table, mapping["heartbeat"].address) == (Table.HOLDING, 1000)
    assert mapping["alarm_bits"].table is Table.INPUT and mapping["alarm_bits"].words == 1
    assert mapping["batch_name"].words * 2 == 16  # "16 bytes"
    assert mapping["position"].codec.encode(1.0) == [0x0000, 0x3F80]  # CDAB: low word first
    assert "debug_info" not in mapping
