"""Store and forward on disk (softplc/adapters/sparkplug/store.py): in order, bounded, across a crash."""

from __future__ import annotations

from pathlib import Path

from softplc.adapters.sparkplug.store import Store


def payload(number: int, size: int = 1000) -> bytes:
    return number.to_bytes(4, "little") + b"x" * (size - 4)


def test_records_come_back_in_order_and_go_once_forwarded_even_after_a_restart(tmp_path: Path) -> None:
    store = Store(tmp_path / "store", max_size=64 * 1024)
    store.open()
    for number in range(40):
        store.append("t01" if number % 2 else "r01", payload(number))
    assert store.count == 40 and len(list((tmp_path / "store").glob("*.spool"))) > 1
    forwarded = []
    first = store.oldest()
    forwarded += [int.from_bytes(p[:4], "little") for _, p in first[:5]]
    store.forwarded(5)
    store.close()
    again = Store(tmp_path / "store", max_size=64 * 1024)  # a new process: what was half forwarded comes again whole
    again.open()
    assert again.count == 40  # at least once: the half-forwarded segment is still on disk
    while again.count:
        records = again.oldest()
        forwarded += [int.from_bytes(p[:4], "little") for _, p in records]
        assert {device for device, _ in records} <= {"t01", "r01"}
        again.forwarded(len(records))
    assert forwarded[5:] == list(range(40)) and list((tmp_path / "store").glob("*.spool")) == []


def test_the_store_stays_bounded_dropping_the_oldest_and_counting_them(tmp_path: Path) -> None:
    store = Store(tmp_path / "store", max_size=64 * 1024)
    store.open()
    for number in range(300):  # 300 kB into 64 kB
        store.append("t01", payload(number))
    assert store.size <= 64 * 1024 and store.dropped + store.count == 300 and store.dropped > 200
    numbers = []
    while store.count:
        records = store.oldest()
        numbers += [int.from_bytes(p[:4], "little") for _, p in records]
        store.forwarded(len(records))
    assert numbers == list(range(300 - len(numbers), 300))  # the newest kept, in order


def test_a_record_torn_by_a_crash_is_cut_off_and_the_rest_kept(tmp_path: Path) -> None:
    store = Store(tmp_path / "store", max_size=1024 * 1024)
    store.open()
    for number in range(3):
        store.append("t01", payload(number, 100))
    store.close()
    segment = next((tmp_path / "store").glob("*.spool"))
    segment.write_bytes(segment.read_bytes()[:-30])  # the last write cut short
    again = Store(tmp_path / "store", max_size=1024 * 1024)
    again.open()
    assert [int.from_bytes(p[:4], "little") for _, p in again.oldest()] == [0, 1]
    again.append("t01", payload(3, 100))  # appends after the cut, not after the garbage
    numbers = []
    while again.count:
        records = again.oldest()
        numbers += [int.from_bytes(p[:4], "little") for _, p in records]
        again.forwarded(len(records))
    assert numbers == [0, 1, 3]
