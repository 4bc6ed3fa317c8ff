"""The live frames' JSON (softplc/adapters/hmi/fanout.py): what the browser parses, from orjson or, for what it does not take, json."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from softplc.adapters.hmi import fanout
from softplc.adapters.hmi.expressions import Item
from softplc.adapters.hmi.fanout import Encoder
from softplc.adapters.hmi.pacing import Pacer
from softplc.core.clock import RealClock
from softplc.core.datatypes import DataType
from softplc.core.tags import Quality, Tag, TagDef

STAMP = 1_767_225_600.125


def tag(name: str, kind: DataType, value: object, *, stamp: float = STAMP, quality: Quality = Quality.GOOD, forced: bool = False) -> Tag:
    item = Tag(TagDef(name=name, type=kind, initial=value), stamp)
    item.value, item.quality, item.forced = value, quality, forced
    return item


def decoded(frame: fanout.Frame) -> list[dict]:
    return [json.loads(chunk) for chunk in frame.chunks]  # what JSON.parse gets: strict JSON, no NaN


async def test_a_frame_carries_every_kind_of_value_as_strict_json() -> None:
    items = [
        tag("level", DataType.FLOAT64, 73.12345678901234),
        tag("tiny", DataType.FLOAT64, 1e-7),
        tag("huge", DataType.FLOAT32, 3.4028234663852886e38),
        tag("nan", DataType.FLOAT64, math.nan),
        tag("up", DataType.FLOAT64, math.inf),
        tag("down", DataType.FLOAT64, -math.inf),
        tag("count", DataType.UINT32, 4_294_967_295),
        tag("offset", DataType.INT16, -32768),
        tag("running", DataType.BOOL, True),
        tag("label", DataType.STRING, 'Größe "A" <b>\n\u2603'),
        tag("late", DataType.FLOAT64, 1.5, stamp=STAMP + 0.25, quality=Quality.UNCERTAIN),
        tag("pinned", DataType.BOOL, False, quality=Quality.BAD, forced=True),
        Item("expr", 2.5, Quality.GOOD, STAMP),
    ]
    (message,) = decoded(await Encoder(Pacer(RealClock())).encode("update", items))
    assert message["type"] == "update" and message["done"] is True
    assert message["time"] == round(STAMP, 3)
    assert message["values"] == {
        "level": 73.12345678901234, "tiny": 1e-7, "huge": 3.4028234663852886e38, "nan": "NaN", "up": "Infinity",
        "down": "-Infinity", "count": 4_294_967_295, "offset": -32768, "running": True, "label": 'Größe "A" <b>\n\u2603',
        "late": 1.5, "pinned": False, "expr": 2.5,
    }
    assert list(message["values"]) == [item.name for item in items]  # in the order given
    assert message["times"] == {"late": round(STAMP + 0.25, 3)}
    assert message["quality"] == {"late": 1, "pinned": 2}
    assert message["forced"] == ["pinned"]


async def test_a_typical_frame_does_not_go_through_json(monkeypatch: pytest.MonkeyPatch) -> None:
    def slow(*args: object, **kwargs: object) -> str:
        raise AssertionError("json.dumps used for a frame orjson can write")

    monkeypatch.setattr(fanout.json, "dumps", slow)
    items = [tag(f"t{index:04d}", DataType.FLOAT64, index / 7) for index in range(1200)]
    messages = decoded(await Encoder(Pacer(RealClock())).encode("update", items))
    assert [len(message["values"]) for message in messages] == [500, 500, 200]  # CHUNK items a message
    assert [message.get("done", False) for message in messages] == [False, False, True]
    assert messages[2]["values"]["t1199"] == 1199 / 7


async def test_what_orjson_does_not_take_is_still_sent() -> None:
    items = [Item("numpy", np.float64(0.5), Quality.GOOD, STAMP), Item("wide", 2**70, Quality.GOOD, STAMP)]
    (message,) = decoded(await Encoder(Pacer(RealClock())).encode("update", items))
    assert message["values"] == {"numpy": 0.5, "wide": 2**70}
