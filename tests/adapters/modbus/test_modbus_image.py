"""The register image: reads see current values; encoding is lazy and limited to the read range."""

from __future__ import annotations

import time

from softplc.adapters.modbus.address_map import Table, build_address_map
from softplc.adapters.modbus.image import RegisterImage
from softplc.config import parse_config
from softplc.core.tagdb import TagDatabase

COUNT = 1000


def make_image():
    text = "version: 1\ntags:\n" + "".join(f"  v{i:04d}: {{type: uint16}}\n" for i in range(COUNT))
    text += "  flag: {type: bool}\n  late: {type: bool}\nservers:\n  modbus: {system_tags: false}\n"
    config = parse_config(text, "image.yaml")
    db = TagDatabase(config.tags, time.time)
    image = RegisterImage(build_address_map(config), db)
    db.on_change(image.note_changed)
    return db, image


def read(image: RegisterImage, table: Table, first: int, count: int) -> list[int]:
    target = [0xDEAD] * count
    image.refresh(table, first, count, target, 0)
    return target


def test_reads_encode_only_what_they_cover_and_see_every_change():
    db, image = make_image()
    db.commit({f"v{i:04d}": i + 1 for i in range(COUNT)})
    assert read(image, Table.HOLDING, 10, 5) == [11, 12, 13, 14, 15]
    words = image.words[Table.HOLDING]
    assert words[:10] == [0] * 10 and words[15:20] == [0] * 5  # not read yet, not encoded yet
    db.commit({"v0012": 999})
    assert read(image, Table.HOLDING, 10, 5) == [11, 12, 999, 14, 15]


def test_a_long_unread_backlog_collapses_but_stays_correct():
    db, image = make_image()
    for round_ in range(5):  # 5000 changes > the 2048-entry cap
        db.commit({f"v{i:04d}": round_ * 10 + i % 7 for i in range(COUNT)})
    assert len(image._backlog) <= 2 * COUNT
    assert read(image, Table.HOLDING, COUNT - 3, 3) == [40 + (COUNT - 3) % 7, 40 + (COUNT - 2) % 7, 40 + (COUNT - 1) % 7]
    assert read(image, Table.HOLDING, 0, 2) == [40, 41]


def test_coils_are_packed_bit_zero_first():
    db, image = make_image()
    assert read(image, Table.COIL, 0, 1) == [0]
    db.commit({"late": True})
    assert read(image, Table.COIL, 0, 1) == [0b10]
    db.commit({"flag": True, "late": False})
    assert read(image, Table.COIL, 0, 1) == [0b01]
