"""Publish, Write and Read responses encoded by response_encoding: byte for byte what asyncua's
`struct_to_binary` makes, for generated responses of every shape (the shapes it leaves to asyncua
included), and a tag change's value encoded once however often it is sent."""

from __future__ import annotations

import dataclasses
import random
from typing import Any

import pytest
from asyncua import ua
from asyncua.common.utils import Buffer
from asyncua.ua.ua_binary import struct_from_binary, struct_to_binary

from softplc.adapters.opcua import response_encoding
from softplc.adapters.opcua.response_encoding import data_value_binary, encode_response
from softplc.core.tags import Quality
from softplc.protocols.opcua_variants import VARIANT_TYPES, TagDataValue, tag_data_value
from tests.opcua_messages import generated, publish_response, read_response, tag_values, write_response


@pytest.mark.parametrize("make", [publish_response, write_response, read_response], ids=lambda make: make.__name__)
@pytest.mark.parametrize("unusual", [False, True], ids=["common", "unusual"])
def test_the_bytes_are_asyncuas(make: Any, unusual: bool) -> None:
    for response in generated(make, f"{make.__name__}-{unusual}", unusual):
        encoded = encode_response(response)
        assert encoded == struct_to_binary(response)
        assert encode_response(response) == encoded  # again, with the tags' values kept encoded
        decoded = struct_from_binary(type(response), Buffer(encoded))
        assert struct_to_binary(decoded) == encoded


def test_the_common_shapes_are_not_left_to_asyncua(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(7)
    responses = [make(rng, False) for make in (publish_response, write_response, read_response) for _ in range(20)]
    expected = [struct_to_binary(response) for response in responses]
    monkeypatch.setattr(response_encoding, "struct_to_binary", lambda response: pytest.fail(f"left to asyncua: {response}"))
    assert [encode_response(response) for response in responses] == expected


def test_other_responses_are_asyncuas() -> None:
    response = ua.BrowseResponse(Results=[ua.BrowseResult(References=[])])
    assert encode_response(response) == struct_to_binary(response)


def test_a_tag_change_is_encoded_once() -> None:
    value = tag_data_value(12.5, ua.VariantType.Double, Quality.GOOD, 1_795_000_000.25)
    first = data_value_binary(value)
    assert first == struct_to_binary(ua.DataValue(value.Value, value.StatusCode, value.SourceTimestamp, value.ServerTimestamp))
    assert data_value_binary(value) is first  # kept: ten subscribers, one encoding
    # asyncua replaces a value whose status is bad (Part 4: its value is null); the copy is encoded anew.
    nulled = dataclasses.replace(value, Value=ua.Variant(None, ua.VariantType.Null))
    assert type(nulled) is TagDataValue
    assert data_value_binary(nulled) == struct_to_binary(ua.DataValue(nulled.Value, value.StatusCode, value.SourceTimestamp, value.ServerTimestamp))


def test_every_tag_type_is_encoded_without_asyncua(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(11)
    values = [value for value in tag_values(rng) if type(value) is TagDataValue]
    expected = [struct_to_binary(ua.DataValue(v.Value, v.StatusCode, v.SourceTimestamp, v.ServerTimestamp)) for v in values]
    monkeypatch.setattr(response_encoding, "_DATA_VALUE", lambda value: pytest.fail(f"left to asyncua: {value}"))
    assert [data_value_binary(value) for value in values] == expected
    assert {value.Value.VariantType for value in values} == set(VARIANT_TYPES.values())
