"""The Sparkplug B wire pieces (softplc/protocols/sparkplug/): payloads, integers, topics, seq and bdSeq.

That other implementations read what we write is tested against pysparkplug in
tests/adapters/sparkplug/; here, the rules of the specification one by one.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from softplc.protocols.sparkplug import payloads
from softplc.protocols.sparkplug import sparkplug_b_pb2 as pb
from softplc.protocols.sparkplug.datatypes import SparkplugType, read_integer, wire_integer
from softplc.protocols.sparkplug.metrics import MetricDefinition
from softplc.protocols.sparkplug.sequence import BirthDeathSequence, MessageSequence
from softplc.protocols.sparkplug.topics import command_target, id_problem, parse_state, state_payload

PROTO = Path(__file__).parents[2] / "softplc/protocols/sparkplug/sparkplug_b.proto"


def test_the_committed_generated_module_matches_the_proto() -> None:
    """Every field of every message in the .proto, by name and number, is in the generated module (regenerate otherwise)."""
    text = re.sub(r"//[^\n]*", "", PROTO.read_text())
    declared = set(re.findall(r"(\w+)\s*=\s*(\d+)\s*;", text))  # fields and enum values
    generated: set[tuple[str, str]] = set()

    def walk(descriptor) -> None:  # noqa: ANN001
        generated.update((field.name, str(field.number)) for field in descriptor.fields)
        for nested in descriptor.nested_types:
            walk(nested)
        for enum in descriptor.enum_types:
            generated.update((value.name, str(value.number)) for value in enum.values)

    walk(pb.Payload.DESCRIPTOR)
    generated.update((value.name, str(value.number)) for value in pb.DESCRIPTOR.enum_types_by_name["DataType"].values)
    assert declared == generated, f"run scripts/generate-sparkplug.sh: differs by {declared ^ generated}"


@pytest.mark.parametrize(("datatype", "value", "wire"), [
    (SparkplugType.INT8, -23, 233), (SparkplugType.INT16, -1, 65535), (SparkplugType.INT16, 30000, 30000),
    (SparkplugType.INT32, -1, 4294967295), (SparkplugType.INT64, -2, 2**64 - 2), (SparkplugType.UINT16, 65535, 65535),
])
def test_integers_travel_as_twos_complement_at_their_width(datatype: SparkplugType, value: int, wire: int) -> None:
    assert wire_integer(datatype, value) == wire
    assert read_integer(datatype, wire) == value


def test_integers_sign_extended_to_32_bits_are_read_and_what_cannot_fit_is_refused() -> None:
    assert read_integer(SparkplugType.INT16, 4294967209) == -87  # Tahu's form of Int16 -87
    assert read_integer(SparkplugType.INT8, 0xFFFFFF80) == -128
    for datatype, raw in ((SparkplugType.INT16, 70000), (SparkplugType.UINT16, 65536), (SparkplugType.INT16, 2**32), (SparkplugType.UINT8, 256)):
        with pytest.raises(ValueError, match="does not fit"):
            read_integer(datatype, raw)


def test_the_node_birth_and_death_carry_the_same_bdseq_and_the_death_no_seq() -> None:
    birth = payloads.decode(payloads.encode_node_birth(1000, 7))
    death = payloads.decode(payloads.encode_node_death(7, 900))
    assert birth.seq == 0 and birth.timestamp == 1000
    assert [(m.name, m.datatype, m.WhichOneof("value")) for m in birth.metrics] == [("bdSeq", 4, "long_value"), ("Node Control/Rebirth", 11, "boolean_value")]
    assert birth.metrics[0].long_value == 7 and birth.metrics[1].boolean_value is False and not birth.metrics[1].HasField("alias")
    assert not death.HasField("seq") and [(m.name, m.long_value) for m in death.metrics] == [("bdSeq", 7)]


def test_a_device_birth_names_every_metric_with_alias_datatype_value_and_properties() -> None:
    level = MetricDefinition("iBL", SparkplugType.FLOAT, alias=3, unit="%", low=0, high=100, description="input buffer level", read_only=True)
    count = MetricDefinition("iBM", SparkplugType.UINT16, alias=4)
    birth = payloads.decode(payloads.encode_device_birth(2000, 1, [(level, 42.5, None, 1990), (count, 7, payloads_bad(), 1995)]))
    first, second = birth.metrics
    assert (first.name, first.alias, first.datatype, first.float_value, first.timestamp) == ("iBL", 3, 9, 42.5, 1990)
    properties = dict(zip(first.properties.keys, first.properties.values))
    assert properties["engUnit"].string_value == "%" and properties["engLow"].double_value == 0 and properties["engHigh"].double_value == 100
    assert properties["documentation"].string_value == "input buffer level" and properties["readOnly"].boolean_value is True
    assert "Quality" not in properties
    quality = dict(zip(second.properties.keys, second.properties.values))["Quality"]
    assert (quality.type, quality.int_value) == (3, 0)  # Int32, BAD


def payloads_bad() -> int:
    from softplc.protocols.sparkplug.datatypes import QUALITY_BAD

    return QUALITY_BAD


def test_data_goes_by_alias_and_historical_data_keeps_its_own_timestamps() -> None:
    level = MetricDefinition("iBL", SparkplugType.FLOAT, alias=3)
    heading = MetricDefinition("heading", SparkplugType.INT16, alias=9)
    data = payloads.decode(payloads.encode_data(3000, 255, [(level, 1.5, None, 2990), (heading, -3, 192, 2995)], by_alias=True))
    assert data.seq == 255 and [(m.alias, m.HasField("name"), m.timestamp) for m in data.metrics] == [(3, False, 2990), (9, False, 2995)]
    assert data.metrics[1].int_value == 65533 and list(data.metrics[1].properties.keys) == ["Quality"]
    stored = payloads.encode_data(3000, None, [(level, 2.5, None, 2500)], by_alias=False)
    forwarded, kept = payloads.as_historical(stored, {"iBL": level}, 9000, by_alias=True)
    metric = forwarded.metrics[0]
    assert kept == 1 and (metric.alias, metric.HasField("name"), metric.is_historical, metric.timestamp, metric.float_value) == (3, False, True, 2500, 2.5)
    assert payloads.as_historical(stored, {}, 9000, by_alias=True)[1] == 0  # a metric the device lost is left out


def test_a_command_value_must_be_of_the_metric_s_type() -> None:
    speed = MetricDefinition("speed", SparkplugType.FLOAT, alias=1)
    count = MetricDefinition("count", SparkplugType.INT16, alias=2)
    assert payloads.command_value(speed, pb.Payload.Metric(alias=1, float_value=0.5)) == 0.5
    assert payloads.command_value(count, pb.Payload.Metric(alias=2, int_value=4294967295)) == -1
    with pytest.raises(payloads.CommandValueError, match="a boolean value for 'speed', which is Float") as wrong:
        payloads.command_value(speed, pb.Payload.Metric(alias=1, boolean_value=True))
    assert wrong.value.wrong_type
    with pytest.raises(payloads.CommandValueError, match="datatype String, but 'speed' is Float"):
        payloads.command_value(speed, pb.Payload.Metric(alias=1, datatype=12, string_value="x"))
    with pytest.raises(payloads.CommandValueError, match="null") as null:
        payloads.command_value(speed, pb.Payload.Metric(alias=1, is_null=True))
    assert not null.value.wrong_type
    with pytest.raises(payloads.MalformedPayload):
        payloads.decode(b"\xff\xff\xff")


def test_seq_starts_at_zero_with_each_birth_and_wraps_after_255() -> None:
    sequence = MessageSequence()
    sequence.value = 254
    assert [sequence.next(), sequence.next(), sequence.next()] == [255, 0, 1]
    assert sequence.birth() == 0 and sequence.next() == 1


def test_bdseq_rises_per_connect_reuses_a_number_no_broker_saw_and_survives_a_restart(tmp_path: Path) -> None:
    path = tmp_path / "sparkplug" / "bdseq"
    sequence = BirthDeathSequence(path)
    assert sequence.for_connect(0) == 0  # the first CONNECT ever
    assert sequence.for_connect(0) == 0  # that attempt never reached the broker: its number was never registered
    assert sequence.for_connect(1) == 1  # the previous CONNECT made a session: the next number
    assert sequence.for_connect(2) == 2
    again = BirthDeathSequence(path)  # the runtime killed and started again
    assert again.for_connect(0) == 3
    path.write_text("255\n")
    assert BirthDeathSequence(path).for_connect(0) == 0  # 255 wraps to 0
    path.write_text("garbage")
    assert BirthDeathSequence(path).for_connect(0) == 0


def test_topics_and_the_primary_host_state() -> None:
    assert command_target("spBv1.0/g/NCMD/n", "g", "n") == ("NCMD", None)
    assert command_target("spBv1.0/g/DCMD/n/r01", "g", "n") == ("DCMD", "r01")
    assert command_target("spBv1.0/g/DCMD/other/r01", "g", "n") is None
    assert command_target("spBv1.0/g/NDATA/n", "g", "n") is None
    assert id_problem("line/1", "edge_node_id") == "edge_node_id 'line/1' contains '/': Sparkplug ids may not contain + / or #"
    assert id_problem("", "group_id") and id_problem("Plant 1", "group_id") is None
    assert parse_state(state_payload(True, 1700000000123)).timestamp == 1700000000123
    for bad, why in ((b"ONLINE", "not JSON"), (b"[1]", "not a JSON object"), (b'{"online": "yes", "timestamp": 1}', "'online'"),
                     (b'{"online": true}', "'timestamp'"), (b"\xff", "not JSON")):
        with pytest.raises(ValueError, match=why):
            parse_state(bad)
