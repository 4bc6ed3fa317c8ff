"""The factsheet (spec §6.15) of one of our simulated robots, from its robots.yaml entry.

Sizes in millimetres become metres; the load capacity (items) is reported as `maxLoadMass`
(one item counts as one kilogram: the master reads it back the same way).
"""

from __future__ import annotations

from typing import Any

from softplc.robotics.robots import RobotSpec

ACTIONS = (("pick", ["NODE"]), ("drop", ["NODE"]), ("cancelOrder", ["INSTANT"]), ("startPause", ["INSTANT"]),
           ("stopPause", ["INSTANT"]), ("initPosition", ["INSTANT"]), ("factsheetRequest", ["INSTANT"]), ("stateRequest", ["INSTANT"]))


def factsheet_of(spec: RobotSpec, version: str, state_interval: float) -> dict[str, Any]:
    """The factsheet body (without header) of a robot for protocol version 2.0 or 2.1."""
    physical: dict[str, Any] = {
        "speedMin": 0.01, "speedMax": spec.max_linear_speed, "accelerationMax": 0.5, "decelerationMax": 0.5,
        "heightMin": spec.height_mm / 1000.0, "heightMax": spec.height_mm / 1000.0,
        "width": spec.width_mm / 1000.0, "length": spec.length_mm / 1000.0,
    }
    if version != "2.0":
        physical["angularSpeedMax"] = spec.max_angular_speed
    body: dict[str, Any] = {
        "typeSpecification": {
            "seriesName": spec.name, "seriesDescription": "softplc simulated differential-drive robot",
            "agvKinematic": "DIFF", "agvClass": "CARRIER", "maxLoadMass": spec.load_capacity,
            "localizationTypes": ["NATURAL"], "navigationTypes": ["AUTONOMOUS"],
        },
        "physicalParameters": physical,
        "protocolLimits": {
            "maxStringLens": {}, "maxArrayLens": {},
            "timing": {"minOrderInterval": 0.1, "minStateInterval": 0.1, "defaultStateInterval": state_interval},
        },
        "protocolFeatures": {
            "optionalParameters": [],
            "agvActions": [{"actionType": name, "actionScopes": scopes} for name, scopes in ACTIONS],
        },
        "agvGeometry": {},
        "loadSpecification": {"loadPositions": ["default"]},
    }
    if version == "2.0":
        body["localizationParameters"] = {}
    return body
