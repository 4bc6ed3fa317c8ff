"""Retained values that cannot be trusted: restored values checked like any write, and a corrupt
retain.sqlite (not a database, or a damaged page) refused with a clear message — or set aside
when the user chooses to start from the initial values (docs/runtime.md, "Retained tags")."""

from __future__ import annotations

import json
import logging
import sqlite3
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from softplc.app.cli import main
from softplc.app.runtime import Runtime
from softplc.core.clock import SimClock
from softplc.engine.retain import RetainError, RetainStore

RETAIN = """
version: 1
tags:
  level: {type: float64, min: 0, max: 1000, initial: 5, retain: true}
  label: {type: string, initial: none, retain: true}
  count: {type: uint32, retain: true}
"""


@pytest.fixture
def build(make_config, tmp_path: Path) -> Callable[..., Runtime]:
    def make(text: str = RETAIN, **options: object) -> Runtime:
        return Runtime(make_config(text), SimClock(), state_dir=tmp_path / "state", **options)  # type: ignore[arg-type]

    return make


def store_rows(path: Path, rows: dict[str, tuple[str, object]]) -> None:
    store = RetainStore(path)
    store.save(rows)
    store.close()


# -- item 13: restored values follow the rules of a write ----------------------------------------


async def test_a_restored_value_outside_a_narrowed_range_falls_back_to_initial_with_a_warning(build, tmp_path: Path, caplog) -> None:
    first = build()
    await first.start()
    first.db.submit([("level", 900.0), ("count", 7)], "operator")
    await first.clock.sleep(0.02)
    await first.stop()
    # the configuration narrows the range: 900 is no longer a value anyone could write
    second = build(RETAIN.replace("max: 1000", "max: 100"))
    caplog.set_level(logging.WARNING)
    await second.start()
    try:
        assert second.db.value("level") == 5.0  # its initial value, not 900
        assert second.db.value("count") == 7  # the others are restored as before
        assert "retained value 900.0 of level (saved as float64) is refused: out of range: 900.0 is above the maximum 100" in caplog.text
        assert "level starts at its initial value 5" in caplog.text
        with pytest.raises(Exception, match="above the maximum 100"):
            second.db.validate("level", 900.0)  # the same verdict as a client's write
    finally:
        await second.stop()


@pytest.mark.parametrize(
    ("name", "stored", "rule"),
    [
        ("level", ("float64", float("nan")), "out of range: NaN is outside the range of a bounded tag"),
        ("level", ("float64", -1.0), "out of range: -1.0 is below the minimum 0"),
        ("label", ("string", "\udcff bad"), "type mismatch"),  # not valid Unicode text (a lone surrogate)
        ("count", ("uint32", -3), "type mismatch"),
    ],
)
async def test_every_write_rule_applies_to_a_restored_value(build, tmp_path: Path, caplog, name: str, stored: tuple[str, object], rule: str) -> None:
    store_rows(tmp_path / "state" / "retain.sqlite", {name: stored})
    runtime = build()
    caplog.set_level(logging.WARNING)
    await runtime.start()
    try:
        assert runtime.db.value(name) == runtime.db[name].definition.initial
        assert f"of {name} (saved as {stored[0]}) is refused: {rule}" in caplog.text
    finally:
        await runtime.stop()


# -- item 14: a corrupt retain.sqlite --------------------------------------------------------------


def damaged_store(path: Path, page: int) -> bytes:
    """A valid store of 300 rows (several pages), then page `page` (1-based) overwritten; returns its bytes."""
    store_rows(path, {f"t{i:03d}": ("uint32", i) for i in range(300)})
    connection = sqlite3.connect(path)
    connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    connection.close()  # the last connection removes the -wal and -shm files, as a clean shutdown does
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]
    data = bytearray(path.read_bytes())
    page_size = int.from_bytes(data[16:18], "big")
    assert len(data) >= page_size * 4
    data[(page - 1) * page_size : page * page_size] = bytes(range(256)) * (page_size // 256)
    path.write_bytes(bytes(data))
    return bytes(data)


CORRUPTIONS: dict[str, Callable[[Path], bytes]] = {
    "not a database": lambda path: (path.write_bytes(b"these are not the retained values you are looking for\n" * 40), path.read_bytes())[1],
    "damaged page": lambda path: damaged_store(path, 2),  # any read of the table fails: "malformed"
    "damaged index page": lambda path: damaged_store(path, 3),  # every row still reads; a save would fail
}


@pytest.fixture(params=sorted(CORRUPTIONS))
def corrupt_file(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[str, Path, bytes]]:
    path = tmp_path / "state" / "retain.sqlite"
    path.parent.mkdir(parents=True, exist_ok=True)
    yield request.param, path, CORRUPTIONS[request.param](path)


async def test_a_corrupt_retain_file_is_refused_and_left_as_it_is(build, corrupt_file) -> None:
    kind, path, content = corrupt_file
    runtime = build()
    with pytest.raises(RetainError) as raised:
        await runtime.start()
    error = raised.value
    assert error.corrupt and error.path == path
    expected = "not an SQLite database" if kind == "not a database" else "damaged"
    assert error.detail.startswith(expected), error.detail
    assert path.read_bytes() == content  # nothing written, nothing moved
    assert sorted(p.name for p in path.parent.iterdir()) == ["retain.sqlite"]
    if kind == "damaged index page":  # found by SQLite's integrity check, though a plain read succeeds
        with sqlite3.connect(path) as connection:
            assert len(connection.execute("SELECT name, type, value FROM retain").fetchall()) == 300


async def test_with_corrupt_retain_initial_the_bad_file_is_kept_aside_and_the_plant_starts_from_initial_values(
    build, corrupt_file, caplog
) -> None:
    kind, path, content = corrupt_file
    (path.parent / "retain.sqlite-wal").write_bytes(b"a journal belonging to the bad file")
    runtime = build(corrupt_retain="initial")
    caplog.set_level(logging.ERROR)
    await runtime.start()
    try:
        assert runtime.db.value("level") == 5.0 and runtime.db.value("count") == 0
        runtime.db.submit([("count", 42)], "operator")
        await runtime.clock.sleep(0.02)
    finally:
        await runtime.stop()
    kept = sorted(p for p in path.parent.iterdir() if ".corrupt-" in p.name)
    assert [p.name.split(".corrupt-")[0] for p in kept] == ["retain.sqlite", "retain.sqlite"]  # the file and its WAL
    bad = next(p for p in kept if not p.name.endswith("-wal"))
    assert bad.read_bytes() == content
    message = next(r.getMessage() for r in caplog.records if "RETAINED VALUES LOST" in r.getMessage())
    assert str(path) in message and str(bad) in message and "every retained tag starts at its initial value" in message
    # a new, sound file took its place and holds what was saved since
    with sqlite3.connect(path) as connection:
        assert json.loads(dict(connection.execute("SELECT name, value FROM retain").fetchall())["count"]) == 42


def test_softplc_run_refuses_a_corrupt_retain_file_with_a_message_and_exit_status_3(tmp_path: Path, capsys) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(RETAIN)
    path = tmp_path / "state" / "retain.sqlite"
    path.parent.mkdir()
    content = CORRUPTIONS["not a database"](path)
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    try:
        code = main(["run", str(plant), "--duration", "0.2", "--no-status", "--no-servers", "--state-dir", str(path.parent)])
        err = capsys.readouterr().err
        assert code == 3, err
        assert "Traceback" not in err
        assert f"softplc: cannot start: the retained values in {path} cannot be used: not an SQLite database (file is not a database)" in err
        assert "run again with --corrupt-retain initial" in err
        assert path.read_bytes() == content
        code = main(["run", str(plant), "--duration", "0.2", "--no-status", "--no-servers", "--state-dir", str(path.parent),
                     "--corrupt-retain", "initial"])
        err = capsys.readouterr().err
        assert code == 0, err
        assert "softplc: ERROR: RETAINED VALUES LOST: " in err
        assert any(p.name.startswith("retain.sqlite.corrupt-") for p in path.parent.iterdir())
        path.unlink()
        path.mkdir()  # not corrupt, but unusable: refused, exit status 1, no --corrupt-retain advice
        code = main(["run", str(plant), "--duration", "0.2", "--no-status", "--no-servers", "--state-dir", str(path.parent),
                     "--corrupt-retain", "initial"])
        err = capsys.readouterr().err
        assert code == 1, err
        assert f"softplc: cannot start: the retained values in {path} cannot be used: cannot be read: " in err
        assert "--corrupt-retain" not in err and "Traceback" not in err
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)


async def test_a_retain_file_that_cannot_be_opened_is_refused_but_not_called_corrupt(build, tmp_path: Path) -> None:
    path = tmp_path / "state" / "retain.sqlite"
    path.mkdir(parents=True)  # e.g. a botched restore: a folder where the file belongs
    runtime = build(corrupt_retain="initial")
    with pytest.raises(RetainError) as raised:
        await runtime.start()
    assert not raised.value.corrupt and raised.value.detail.startswith("cannot be read: ")
    assert path.is_dir() and [p.name for p in path.parent.iterdir()] == ["retain.sqlite"]  # never set aside
