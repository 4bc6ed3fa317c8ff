"""What a birth says of a metric: its name, alias, datatype and properties (no protobuf here)."""

from __future__ import annotations

from dataclasses import dataclass

from softplc.protocols.sparkplug.datatypes import SparkplugType

REBIRTH = "Node Control/Rebirth"  # §5.12: every NBIRTH has it, Boolean false, never with an alias
BD_SEQ = "bdSeq"  # §5.2: in the NDEATH will and the NBIRTH, Int64


@dataclass(frozen=True, slots=True)
class MetricDefinition:
    """One metric of a birth certificate.

    `unit`, `low`, `high`, `description` and `read_only` travel as the metric's property set
    under the keys of Ignition's tag properties (engUnit, engLow, engHigh, documentation,
    readOnly), which Cirrus Link's MQTT Engine maps onto its tags; the specification names no
    keys but `Quality`.
    """

    name: str
    datatype: SparkplugType
    alias: int | None = None
    unit: str = ""
    low: float | None = None
    high: float | None = None
    description: str = ""
    read_only: bool = False
