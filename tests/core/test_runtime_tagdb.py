"""Tag types and the tag database: coercion, validation rules, the journal, notifications."""

from __future__ import annotations

import math

import numpy as np
import pytest

from softplc.core.datatypes import DataType, TypeMismatch
from softplc.core.roles import Role
from softplc.core.tagdb import Origin, Rule, TagDatabase, WriteRejected
from softplc.core.tags import Access, Quality, TagDef


@pytest.mark.parametrize(
    ("data_type", "value", "expected"),
    [
        (DataType.BOOL, True, True),
        (DataType.BOOL, 0, False),
        (DataType.BOOL, 1, True),
        (DataType.INT16, -32768, -32768),
        (DataType.INT16, 3.0, 3),
        (DataType.UINT16, 65535, 65535),
        (DataType.INT32, 2**31 - 1, 2**31 - 1),
        (DataType.UINT32, 2**32 - 1, 2**32 - 1),
        (DataType.FLOAT64, 3, 3.0),
        (DataType.FLOAT64, math.inf, math.inf),
        (DataType.FLOAT32, 0.1, 0.10000000149011612),
        (DataType.STRING, "héllo", "héllo"),
        # NumPy scalars (what scikit-learn returns) become plain Python values
        (DataType.INT16, np.int64(7), 7),
        (DataType.BOOL, np.bool_(True), True),
        (DataType.FLOAT64, np.float32(0.5), 0.5),
        (DataType.UINT16, np.float64(4.0), 4),
    ],
)
def test_coerce_accepts_lossless_values(data_type: DataType, value: object, expected: object) -> None:
    result = data_type.coerce(value)
    assert result == expected and type(result) is type(expected)


@pytest.mark.parametrize(
    ("data_type", "value", "message"),
    [
        (DataType.BOOL, 2, "expected bool, got int 2"),
        (DataType.BOOL, "true", "expected bool, got str 'true'"),
        (DataType.INT16, 32768, "32768 does not fit in int16 (-32768..32767)"),
        (DataType.UINT16, -1, "-1 does not fit in uint16 (0..65535)"),
        (DataType.UINT32, 2**32, "4294967296 does not fit in uint32 (0..4294967295)"),
        (DataType.INT32, 2.5, "expected int32, got non-integral number 2.5"),
        (DataType.INT32, True, "expected int32, got bool True"),
        (DataType.FLOAT64, "1.5", "expected float64, got str '1.5'"),
        (DataType.FLOAT32, 1e39, "1e+39 does not fit in float32"),
        (DataType.STRING, 5, "expected string, got int 5"),
        (DataType.INT16, np.int64(40000), "40000 does not fit in int16 (-32768..32767)"),
    ],
)
def test_coerce_rejects_lossy_values(data_type: DataType, value: object, message: str) -> None:
    with pytest.raises(TypeMismatch) as raised:
        data_type.coerce(value)
    assert str(raised.value) == message


def make_db() -> TagDatabase:
    now = [100.0]
    db = TagDatabase(
        [
            TagDef("level", DataType.FLOAT32, 0.0, min=0, max=100),
            TagDef("count", DataType.UINT16, 5),
            TagDef("status", DataType.STRING, "", access=Access.RO),
            TagDef("run", DataType.BOOL, False),
        ],
        lambda: now[0],
    )
    db.test_now = now  # type: ignore[attr-defined]
    return db


def test_validate_applies_every_rule() -> None:
    db = make_db()
    assert db.validate("level", 50) == 50.0
    cases = [
        ("nope", 1, True, Rule.UNKNOWN_TAG, "nope: unknown tag: no such tag"),
        ("status", "x", True, Rule.READ_ONLY, "status: read-only: the tag is read-only for clients"),
        ("count", 1.5, True, Rule.TYPE_MISMATCH, "count: type mismatch: expected uint16, got non-integral number 1.5"),
        ("level", 100.5, True, Rule.OUT_OF_RANGE, "level: out of range: 100.5 is above the maximum 100"),
        ("level", -1, True, Rule.OUT_OF_RANGE, "level: out of range: -1.0 is below the minimum 0"),
    ]
    for name, value, client, rule, message in cases:
        with pytest.raises(WriteRejected) as raised:
            db.validate(name, value)
        assert (raised.value.tag, raised.value.rule, str(raised.value)) == (name, rule, message)
    assert db.validate("status", "ok", role=None) == "ok"  # programs may write ro tags


def test_the_runtimes_own_writes_of_the_exact_type_are_taken_as_they_are_and_the_rest_still_checked() -> None:
    db = TagDatabase([TagDef("x", DataType.FLOAT64, 0.0), TagDef("on", DataType.BOOL, False),
                      TagDef("bounded", DataType.FLOAT64, 0.0, min=0.0, max=1.0), TagDef("n", DataType.INT16, 0)], now=lambda: 0.0)
    assert db.validate("x", math.nan, role=None) != db.validate("x", math.nan, role=None)  # NaN, as coerce gives it
    assert db.validate("x", 2.5, role=None) == 2.5 and db.validate("on", True, role=None) is True
    converted = db.validate("x", np.float64(0.5), role=None)  # a float subclass: converted to a plain float
    assert converted == 0.5 and type(converted) is float
    assert db.validate("x", 3, role=None) == 3.0 and type(db.validate("x", 3, role=None)) is float
    assert db.validate("on", 1, role=None) is True
    for name, value, rule in (("bounded", 1.5, Rule.OUT_OF_RANGE), ("bounded", math.nan, Rule.OUT_OF_RANGE),
                              ("on", 2, Rule.TYPE_MISMATCH), ("x", "1", Rule.TYPE_MISMATCH), ("n", 1.5, Rule.TYPE_MISMATCH),
                              ("n", 40_000, Rule.TYPE_MISMATCH)):
        with pytest.raises(WriteRejected) as raised:
            db.validate(name, value, role=None)
        assert raised.value.rule is rule, (name, value)


def test_submit_journals_valid_items_and_applies_them_together_in_order() -> None:
    db = make_db()
    changes: list[list[str]] = []
    unsubscribe = db.on_change(lambda tags: changes.append([f"{t.name}={t.value}" for t in tags]))
    results = db.submit([("level", 10), ("count", -1), ("level", 20), ("run", 1)], "client")
    assert [r is None for r in results] == [True, False, True, True]
    assert db.value("level") == 0.0 and changes == []
    db.test_now[0] = 101.0  # type: ignore[attr-defined]
    assert db.apply_journal() == 3
    assert db.value("level") == 20.0 and db["level"].timestamp == 101.0 and db.value("run") is True
    assert changes == [["level=20.0", "run=True"]]  # one notification per applied batch
    assert db.apply_journal() == 0
    db.submit([("level", 20)], "client")  # unchanged: applied, nobody notified
    db.apply_journal()
    assert len(changes) == 1
    unsubscribe()
    db.submit([("level", 30)], "client")
    db.apply_journal()
    assert len(changes) == 1 and db.value("level") == 30.0


def test_commit_notifies_only_changes_and_restores_good_quality() -> None:
    db = make_db()
    seen: list[str] = []
    db.on_change(lambda tags: seen.extend(t.name for t in tags))
    db.submit_quality(["count"], Quality.BAD, "driver")
    db.apply_journal()
    assert db["count"].quality is Quality.BAD and seen == ["count"]
    changed = db.commit({"count": 5, "level": 0.0})  # same value but BAD → GOOD is a change
    assert [t.name for t in changed] == ["count"] and db["count"].quality is Quality.GOOD


def test_a_quality_change_keeps_the_value_the_tag_has_when_it_is_applied() -> None:
    # A driver journals a new value, then (before the next boundary) a quality change: the value
    # stays the new one. The quality write must not carry the value of the moment it was submitted.
    db = make_db()
    db.submit([("count", 7)], "driver")
    db.submit_quality(["count"], Quality.UNCERTAIN, "driver")
    db.apply_journal()
    assert (db.value("count"), db["count"].quality) == (7, Quality.UNCERTAIN)
    db.commit({"count": 8})  # a program's output, applied at once, then a quality change
    db.submit_quality(["count"], Quality.BAD, "driver")
    db.apply_journal()
    assert (db.value("count"), db["count"].quality) == (8, Quality.BAD)


def test_a_failing_subscriber_does_not_stop_the_others(caplog) -> None:
    db = make_db()
    seen: list[str] = []

    def broken(tags: object) -> None:
        raise RuntimeError("subscriber bug")

    db.on_change(broken)
    db.on_change(lambda tags: seen.extend(t.name for t in tags))
    db.commit({"count": 6})
    assert seen == ["count"] and db.value("count") == 6
    assert "subscriber bug" in caplog.text


def test_snapshot_and_duplicates() -> None:
    db = make_db()
    assert db.snapshot(["count", "run"]) == {"count": 5, "run": False}
    assert set(db.snapshot()) == {"level", "count", "status", "run"}
    assert len(db) == 4 and "level" in db and db.get("nope") is None
    with pytest.raises(ValueError):
        TagDatabase([TagDef("a", DataType.BOOL, False), TagDef("a", DataType.BOOL, False)], lambda: 0.0)


def test_string_must_be_valid_unicode_text_on_every_path() -> None:
    # asyncua decodes invalid UTF-8 with surrogateescape: b"\xff" arrives as "\udcff".
    with pytest.raises(TypeMismatch, match="not valid UTF-8 text: invalid character at position 2"):
        DataType.STRING.coerce("ok\udcff")
    db = make_db()
    [rejected] = db.submit([("status", "bad\udcff")], Origin("test", role=Role.ENGINEER))
    assert rejected is not None and rejected.rule is Rule.TYPE_MISMATCH
    with pytest.raises(WriteRejected):  # programs and drivers too: one rule for strings
        db.validate("status", "\ud800", role=None)
    assert db.validate("status", "Grüße 工場", role=None) == "Grüße 工場"


def test_roles_decide_what_a_client_may_write() -> None:
    db = TagDatabase(
        [
            TagDef("level", DataType.FLOAT32, 0.0),
            TagDef("status", DataType.STRING, "", access=Access.RO),
            TagDef("_sys.state", DataType.STRING, "", access=Access.RO, runtime_only=True),
            TagDef("_sys.reset_faults", DataType.BOOL, False),
        ],
        lambda: 0.0,
    )
    expected = {
        Role.VIEWER: {"level": Rule.ACCESS_DENIED, "status": Rule.ACCESS_DENIED, "_sys.state": Rule.READ_ONLY, "_sys.reset_faults": Rule.ACCESS_DENIED},
        Role.OPERATOR: {"level": None, "status": Rule.READ_ONLY, "_sys.state": Rule.READ_ONLY, "_sys.reset_faults": None},
        Role.ENGINEER: {"level": None, "status": None, "_sys.state": Rule.READ_ONLY, "_sys.reset_faults": None},
    }
    values = {"level": 1.0, "status": "x", "_sys.state": "RUNNING", "_sys.reset_faults": True}
    for role, rules in expected.items():
        results = db.submit(list(values.items()), Origin("test", role=role))
        assert {name: (r.rule if r else None) for name, r in zip(values, results)} == rules, role
        assert {name: db.writable(name, role) for name in values} == {name: rule is None for name, rule in rules.items()}
    # Inside the runtime (drivers), no access rule applies except the type's.
    assert db.submit([("status", "driven")], Origin("driver", role=None)) == [None]


def test_write_listeners_see_every_client_write_with_its_origin() -> None:
    db = make_db()
    events: list = []
    db.on_write(events.extend)
    alice = Origin("hmi", user="alice", peer="127.0.0.1", role=Role.OPERATOR)
    db.submit([("level", 10), ("count", -1), ("status", "x")], alice)
    db.refused(alice, "level", "12", Rule.INVALID_REQUEST, "a quality was sent")
    db.submit([("level", 11)], Origin("fleet:r01", role=None))  # inside the runtime: not reported
    assert [(e.tag, e.old, e.new, e.rule, e.origin) for e in events] == [
        ("level", 0.0, 10.0, None, alice),
        ("count", 5, -1, Rule.TYPE_MISMATCH, alice),
        ("status", "", "x", Rule.READ_ONLY, alice),
        ("level", 0.0, "12", Rule.INVALID_REQUEST, alice),
    ]
    assert [e.accepted for e in events] == [True, False, False, False]
    assert events[0].time == 100.0 and str(alice) == "hmi:alice@127.0.0.1"

    def broken(_events: object) -> None:
        raise RuntimeError("listener bug")

    db.on_write(broken)  # a broken listener never refuses or loses a write
    assert db.submit([("level", 12)], alice) == [None]
    db.apply_journal()
    assert db.value("level") == 12.0


def test_atomic_submit_journals_all_or_nothing() -> None:
    db = make_db()
    results = db.submit([("level", 10), ("count", 70000), ("run", True)], "modbus", atomic=True)
    assert [r.rule if r else None for r in results] == [Rule.TYPE_MISMATCH] * 3
    assert "not applied" in str(results[0]) and db.apply_journal() == 0
    assert db.submit([("level", 10), ("run", True)], "modbus", atomic=True) == [None, None]
    assert db.apply_journal() == 2


@pytest.mark.parametrize(
    ("data_type", "text", "expected"),
    [(DataType.BOOL, "on", True), (DataType.BOOL, "False", False), (DataType.INT16, " -42 ", -42),
     (DataType.UINT16, "3.0", 3), (DataType.FLOAT32, "1e3", 1000.0), (DataType.STRING, " as typed ", " as typed ")],
)
def test_parse_reads_what_a_person_typed(data_type: DataType, text: str, expected: object) -> None:
    assert data_type.parse(text) == expected and type(data_type.parse(text)) is type(expected)


@pytest.mark.parametrize(
    ("data_type", "text", "message"),
    [(DataType.BOOL, "maybe", "expected bool (true/false, 1/0, on/off), got 'maybe'"),
     (DataType.INT16, "12abc", "expected int16, got '12abc'"), (DataType.UINT16, "-1", "-1 does not fit in uint16 (0..65535)")],
)
def test_parse_refuses_what_is_not_a_value_of_the_type(data_type: DataType, text: str, message: str) -> None:
    with pytest.raises(TypeMismatch, match=message.replace("(", r"\(").replace(")", r"\)")):
        data_type.parse(text)
