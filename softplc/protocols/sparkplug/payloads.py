"""Sparkplug B payloads encoded and decoded with the generated protobuf code (sparkplug_b_pb2).

    encode_data(timestamp, seq, changes, by_alias=True)       # a DDATA: the metrics that changed
    decode(raw)                                               # any payload, or MalformedPayload
    command_value(definition, metric)                         # a command's value for the metric, checked

Timestamps are integers: milliseconds since the epoch, UTC (§6.4.1). A change is
`(definition, value, quality, timestamp)`, `quality` being a Quality code (§6.4.7) to send as
the metric's `Quality` property, or None to send none (a good value whose quality did not change).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from google.protobuf.message import DecodeError

from softplc.protocols.sparkplug import sparkplug_b_pb2 as pb
from softplc.protocols.sparkplug.datatypes import INTEGER_WIDTHS, SparkplugType, read_integer, wire_integer
from softplc.protocols.sparkplug.metrics import BD_SEQ, REBIRTH, MetricDefinition

Change = tuple[MetricDefinition, Any, "int | None", int]

_STRING = int(SparkplugType.STRING)
_DOUBLE = int(SparkplugType.DOUBLE)
_BOOLEAN = int(SparkplugType.BOOLEAN)
_INT32 = int(SparkplugType.INT32)
_INT64 = int(SparkplugType.INT64)
_FIELDS = {datatype: datatype.field for datatype in SparkplugType}


class MalformedPayload(ValueError):
    """Bytes that are no Sparkplug B payload."""


class CommandValueError(ValueError):
    """A command's metric whose value cannot be the metric's: `wrong_type` tells a wrong datatype from a missing value."""

    def __init__(self, message: str, *, wrong_type: bool) -> None:
        super().__init__(message)
        self.wrong_type = wrong_type


def decode(raw: bytes) -> Any:
    """The payload in `raw` (a pb.Payload); MalformedPayload when it is none."""
    payload = pb.Payload()
    try:
        payload.ParseFromString(raw)
    except DecodeError as error:
        raise MalformedPayload(f"not a Sparkplug B payload ({error})") from None
    return payload


def encode_node_death(bd_seq: int, timestamp: int) -> bytes:
    """An NDEATH: the bdSeq metric alone and no seq (§4.2.3)."""
    payload = pb.Payload(timestamp=timestamp)
    payload.metrics.add(name=BD_SEQ, timestamp=timestamp, datatype=_INT64, long_value=bd_seq)
    return payload.SerializeToString()


def encode_node_birth(timestamp: int, bd_seq: int, extra: Iterable[tuple[MetricDefinition, Any]] = ()) -> bytes:
    """An NBIRTH: seq 0, bdSeq, `Node Control/Rebirth` = false without an alias (§5.12), then `extra` metrics."""
    payload = pb.Payload(timestamp=timestamp, seq=0)
    payload.metrics.add(name=BD_SEQ, timestamp=timestamp, datatype=_INT64, long_value=bd_seq)
    payload.metrics.add(name=REBIRTH, timestamp=timestamp, datatype=_BOOLEAN, boolean_value=False)
    for definition, value in extra:
        _fill_birth(payload.metrics.add(), definition, value, None, timestamp)
    return payload.SerializeToString()


def encode_device_birth(timestamp: int, seq: int, metrics: Iterable[Change], *, properties: bool = True) -> bytes:
    """A DBIRTH: every metric of the device with name, alias, datatype, value and (`properties`) unit, range, description, read-only."""
    payload = pb.Payload(timestamp=timestamp, seq=seq)
    add = payload.metrics.add
    for definition, value, quality, stamp in metrics:
        _fill_birth(add(), definition, value, quality, stamp, properties)
    return payload.SerializeToString()


def encode_data(timestamp: int, seq: int | None, changes: Iterable[Change], *, by_alias: bool, historical: bool = False) -> bytes:
    """A DDATA (or NDATA): the changes in order, by alias when aliases are in use, else by name."""
    payload = pb.Payload(timestamp=timestamp)
    if seq is not None:
        payload.seq = seq
    add = payload.metrics.add
    # The hot path of a busy plant (every change of every scan): one `add` with keywords per
    # metric, the most common value fields first, costs about half of setting fields one by one.
    for definition, value, quality, stamp in changes:
        key = {"alias": definition.alias} if by_alias else {"name": definition.name}
        field = _FIELDS[definition.datatype]
        if value is None:
            metric = add(timestamp=stamp, is_null=True, **key)
        elif field == "int_value" or field == "long_value":
            metric = add(timestamp=stamp, **key, **{field: value if value >= 0 else wire_integer(definition.datatype, value)})
        else:
            metric = add(timestamp=stamp, **key, **{field: value})
        if historical:
            metric.is_historical = True
        if quality is not None:
            _quality(metric, quality)
    return payload.SerializeToString()


def encode_device_death(timestamp: int, seq: int) -> bytes:
    """A DDEATH: no metrics, the node's next seq (§4.2.4)."""
    return pb.Payload(timestamp=timestamp, seq=seq).SerializeToString()


def as_historical(raw: bytes, definitions: Mapping[str, MetricDefinition], timestamp: int, *, by_alias: bool) -> tuple[Any, int]:
    """A stored data payload (metrics by name, no seq) made ready to forward: historical, by alias; the caller numbers it.

    Metrics the device no longer has (the configuration changed meanwhile) are left out; returns
    the payload (a pb.Payload without seq) and how many metrics it kept.
    """
    stored = decode(raw)
    payload = pb.Payload(timestamp=timestamp)
    kept = 0
    for metric in stored.metrics:
        definition = definitions.get(metric.name)
        if definition is None:
            continue
        copy = payload.metrics.add()
        copy.CopyFrom(metric)
        copy.is_historical = True
        if by_alias and definition.alias is not None:
            copy.ClearField("name")
            copy.alias = definition.alias
        kept += 1
    return payload, kept


def command_value(definition: MetricDefinition, metric: Any) -> Any:
    """The value a command's `metric` writes to `definition`'s metric; CommandValueError if it is not one of its type."""
    datatype = definition.datatype
    if metric.HasField("datatype") and metric.datatype != int(datatype):
        label = _label(metric.datatype)
        raise CommandValueError(f"datatype {label}, but '{definition.name}' is {datatype.label}", wrong_type=True)
    field = metric.WhichOneof("value")
    if metric.is_null or field is None:
        raise CommandValueError(f"no value for '{definition.name}' (null)", wrong_type=False)
    raw = getattr(metric, field)
    if datatype in INTEGER_WIDTHS:
        if field not in ("int_value", "long_value"):
            raise CommandValueError(f"a {_field_type(field)} value for '{definition.name}', which is {datatype.label}", wrong_type=True)
        try:
            return read_integer(datatype, raw)
        except ValueError as error:
            raise CommandValueError(str(error), wrong_type=True) from None
    expected = {SparkplugType.FLOAT: ("float_value", "double_value"), SparkplugType.DOUBLE: ("double_value", "float_value"),
                SparkplugType.BOOLEAN: ("boolean_value",), SparkplugType.STRING: ("string_value",),
                SparkplugType.TEXT: ("string_value",)}[datatype]
    if field not in expected:
        raise CommandValueError(f"a {_field_type(field)} value for '{definition.name}', which is {datatype.label}", wrong_type=True)
    return raw


# -- inside -------------------------------------------------------------------------------------


def _fill_birth(metric: Any, definition: MetricDefinition, value: Any, quality: int | None, stamp: int, described: bool = True) -> None:
    metric.name = definition.name
    if definition.alias is not None:
        metric.alias = definition.alias
    metric.timestamp = stamp
    metric.datatype = int(definition.datatype)
    _set_value(metric, definition.datatype, value)
    properties = metric.properties
    if quality is not None:
        _property(properties, "Quality", _INT32, int_value=quality)
    if not described:
        return
    if definition.unit:
        _property(properties, "engUnit", _STRING, string_value=definition.unit)
    if definition.low is not None:
        _property(properties, "engLow", _DOUBLE, double_value=float(definition.low))
    if definition.high is not None:
        _property(properties, "engHigh", _DOUBLE, double_value=float(definition.high))
    if definition.description:
        _property(properties, "documentation", _STRING, string_value=definition.description)
    _property(properties, "readOnly", _BOOLEAN, boolean_value=definition.read_only)


def _set_value(metric: Any, datatype: SparkplugType, value: Any) -> None:
    if value is None:
        metric.is_null = True
    elif datatype in INTEGER_WIDTHS:
        setattr(metric, datatype.field, wire_integer(datatype, value))
    else:
        setattr(metric, datatype.field, value)


def _quality(metric: Any, quality: int) -> None:
    _property(metric.properties, "Quality", _INT32, int_value=quality)


def _property(properties: Any, key: str, datatype: int, **value: Any) -> None:
    properties.keys.append(key)
    properties.values.add(type=datatype, **value)


def _label(datatype: int) -> str:
    try:
        return SparkplugType(datatype).label
    except ValueError:
        name = pb.DataType.Name(datatype) if datatype in pb.DataType.values() else f"#{datatype}"
        return name


def _field_type(field: str) -> str:
    return {"int_value": "uint32", "long_value": "uint64", "float_value": "float", "double_value": "double",
            "boolean_value": "boolean", "string_value": "string", "bytes_value": "bytes", "dataset_value": "DataSet",
            "template_value": "Template"}.get(field, field)
