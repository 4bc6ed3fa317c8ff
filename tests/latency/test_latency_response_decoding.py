"""The latency client's decoding of Publish and Write responses: the objects asyncua's
`struct_from_binary` gives, for generated responses of every shape (those left to asyncua
included), for damaged ones too (the same result or the same refusal)."""

from __future__ import annotations

import random
from typing import Any

import pytest
from asyncua import ua
from asyncua.common.utils import Buffer
from asyncua.ua.ua_binary import struct_from_binary, struct_to_binary

from softplc.latency import response_decoding
from softplc.latency.response_decoding import decode_publish_response, decode_write_response
from tests.opcua_messages import generated, publish_response, write_response

DECODERS: dict[type, Any] = {ua.PublishResponse: decode_publish_response, ua.WriteResponse: decode_write_response}


def asyncuas(kind: type, encoded: bytes) -> Any:
    """asyncua's decoding of `encoded`, or the type of the error it raises."""
    try:
        return struct_from_binary(kind, Buffer(encoded))
    except Exception as error:  # noqa: BLE001 - compared below
        return type(error)


def ours(kind: type, encoded: bytes) -> Any:
    try:
        return DECODERS[kind](Buffer(encoded))
    except Exception as error:  # noqa: BLE001
        return type(error)


@pytest.mark.parametrize("make", [publish_response, write_response], ids=lambda make: make.__name__)
@pytest.mark.parametrize("unusual", [False, True], ids=["common", "unusual"])
def test_the_objects_are_asyncuas(make: Any, unusual: bool) -> None:
    for response in generated(make, f"decode-{make.__name__}-{unusual}", unusual):
        encoded = struct_to_binary(response)
        kind = type(response)
        assert ours(kind, encoded) == asyncuas(kind, encoded) == struct_from_binary(kind, Buffer(encoded))


def test_the_common_shapes_are_not_left_to_asyncua(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(3)
    responses = [publish_response(rng, False, scalars_only=True) for _ in range(50)] + [write_response(rng, False) for _ in range(20)]
    encoded = [struct_to_binary(response) for response in responses]
    expected = [struct_from_binary(type(response), Buffer(data)) for response, data in zip(responses, encoded)]
    monkeypatch.setattr(response_decoding, "struct_from_binary", lambda kind, data: pytest.fail(f"left to asyncua: {kind}"))
    assert [DECODERS[type(response)](Buffer(data)) for response, data in zip(responses, encoded)] == expected


@pytest.mark.parametrize("make", [publish_response, write_response], ids=lambda make: make.__name__)
def test_damaged_responses_decode_or_fail_as_asyncuas(make: Any) -> None:
    rng = random.Random(f"damaged-{make.__name__}")
    for _ in range(300):
        response = make(rng, rng.random() < 0.2, **({"scalars_only": True} if make is publish_response else {}))
        data = bytearray(struct_to_binary(response))
        if rng.random() < 0.3:
            del data[rng.randrange(len(data)):]  # cut short
        for _ in range(rng.randint(1, 3)):
            if data:
                data[rng.randrange(len(data))] = rng.randrange(256)
        kind = type(response)
        expected, got = asyncuas(kind, bytes(data)), ours(kind, bytes(data))
        if isinstance(expected, type):
            assert got is expected
        else:
            assert got == expected or repr(got) == repr(expected)  # a damaged float may be a NaN, unequal to itself
