"""Engineering units as OPC UA EUInformation (UNECE Recommendation 20 codes where one exists)."""

from __future__ import annotations

from asyncua import ua

UNECE_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"

# Units this plant uses, by the text written in tagdb.yaml → UNECE common code.
_UNECE_CODES: dict[str, str] = {
    "m": "MTR", "mm": "MMT", "cm": "CMT", "km": "KMT",
    "s": "SEC", "ms": "C26", "us": "B98", "min": "MIN", "h": "HUR",
    "%": "P1", "m/s": "MTS", "m/s2": "MSK", "rad": "C81", "rad/s": "2A", "deg": "DD", "°": "DD",
    "kg": "KGM", "g": "GRM", "t": "TNE", "°C": "CEL", "degC": "CEL", "K": "KEL",
    "Hz": "HTZ", "V": "VLT", "mV": "2Z", "A": "AMP", "mA": "4K", "W": "WTT", "kW": "KWT",
    "Pa": "PAL", "kPa": "KPA", "bar": "BAR", "rpm": "RPM", "1/min": "RPM", "items": "C62", "pcs": "H87",
    "l": "LTR", "l/min": "L2", "N": "NEW", "Nm": "NU",
}


def unit_id(unit: str) -> int:
    """The EUInformation UnitId of a unit text, or -1 when it has no UNECE code."""
    code = _UNECE_CODES.get(unit)
    if code is None:
        return -1
    number = 0
    for char in code:
        number = (number << 8) | ord(char)
    return number


def eu_information(unit: str) -> ua.EUInformation:
    """The EngineeringUnits property value for a tag's `unit:` text."""
    return ua.EUInformation(
        NamespaceUri=UNECE_NAMESPACE,
        UnitId=unit_id(unit),
        DisplayName=ua.LocalizedText(unit),
        Description=ua.LocalizedText(unit),
    )
