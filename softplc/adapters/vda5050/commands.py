"""What the master control offers the HMI and `softplc vda5050`: registered queries, and instant actions (engineer).

    vda5050.vehicles     every vehicle: connection, liveness, order, base/horizon, errors, battery, mode, pose
    vda5050.roadmap      the roadmap's nodes and lanes (the HMI draws them on the map)
    vda5050.orders       each vehicle's order as coordinates: the base (drawn solid) and the horizon (dashed)
    vda5050.factsheets   each vehicle's factsheet figures and how they differ from robots.yaml (which wins)
    vda5050.instant_action {robot, action, parameters}   startPause, stopPause, cancelOrder, initPosition,
                         factsheetRequest, stateRequest — engineer only, audited like every command
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Mapping
from dataclasses import asdict
from typing import Any

from softplc.core.commands import CommandRefused, Commands, Permission
from softplc.core.origin import Origin
from softplc.protocols.vda5050.messages import action

INSTANT_ACTIONS = ("startPause", "stopPause", "cancelOrder", "initPosition", "factsheetRequest", "stateRequest")


def register_commands(commands: Commands, master: Any) -> list[Callable[[], None]]:
    """Register the `vda5050.*` queries and the instant-action command for `master` (the VdaMaster); returns their unregisters."""

    def vehicles(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        now = master.plant.clock.now() if master.plant is not None else 0.0
        rows = []
        for link in master.links.values():
            state = link.state
            trip = link.trip
            rows.append({
                "robot": link.id, "manufacturer": link.identity.manufacturer, "serial_number": link.identity.serial_number,
                "alive": link.alive, "connection": link.connection or "-",
                "state_age": round(now - link.last_state_at, 3) if link.states else None,
                "order": f"{trip.order_id}/{trip.update_id}" if trip is not None else "",
                "base": trip.base if trip is not None else [], "horizon": trip.horizon if trip is not None else [],
                "waiting": master.control.traffic.waits[link.id].text if master.control and link.id in master.control.traffic.waits else "",
                "errors": link.error_text(state), "battery": state.battery_charge if state else None,
                "mode": state.operating_mode if state else "", "paused": state.paused if state else False,
                "position": list(state.position) if state is not None and state.position is not None else None,
                "last_node": state.last_node_id if state else "", "resends": trip.resends if trip is not None else 0,
                "states": link.states, "bad_messages": link.bad_messages,
            })
        return rows

    def roadmap(arguments: Mapping[str, Any], origin: Origin) -> dict[str, Any]:
        road = master.roadmap
        lanes = {}
        for lane in road.lanes.values():
            key = tuple(sorted((lane.start, lane.end)))
            one_way = road.lane(lane.end, lane.start) is None
            lanes.setdefault(key, {"from": lane.start, "to": lane.end, "one_way": one_way})
        return {
            "map_id": road.map_id,
            "nodes": [{"id": node.id, "x": node.x, "y": node.y, "station": node.station, "name": node.name} for node in road.nodes.values()],
            "lanes": list(lanes.values()),
        }

    def orders(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        road = master.roadmap
        rows = []
        for link in master.links.values():
            trip = link.trip
            if trip is None:
                continue
            state = link.state
            position = trip.position(state.last_node_id, state.last_node_sequence_id) if state is not None and \
                state.order_id == trip.order_id else 0
            start = max(position, 0)
            point = [[road.nodes[node].x, road.nodes[node].y] for node in trip.route]
            rows.append({"robot": link.id, "order_id": trip.order_id, "order_update_id": trip.update_id,
                         "acknowledged": trip.acknowledged, "goal_node": trip.goal_node,
                         "base": point[start: trip.released + 1], "horizon": point[trip.released:],
                         "route": trip.route, "released": trip.released})
        return rows

    def factsheets(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        return [{"robot": link.id, "factsheet": asdict(link.factsheet) if link.factsheet is not None else None,
                 "differences": master.factsheet_differences.get(link.id, [])} for link in master.links.values()]

    async def instant_action(arguments: Mapping[str, Any], origin: Origin) -> dict[str, Any]:
        robot = arguments.get("robot")
        link = master.links.get(robot) if isinstance(robot, str) else None
        if link is None:
            raise CommandRefused(f"vda5050.instant_action: no VDA 5050 vehicle {robot!r}; vehicles: {', '.join(master.links) or 'none'}")
        kind = arguments.get("action")
        if kind not in INSTANT_ACTIONS:
            raise CommandRefused(f"vda5050.instant_action: action must be one of {', '.join(INSTANT_ACTIONS)}, not {kind!r}")
        parameters = arguments.get("parameters") or {}
        if not isinstance(parameters, dict):
            raise CommandRefused("vda5050.instant_action: parameters must be a mapping of key to value")
        if kind == "initPosition" and not all(isinstance(parameters.get(key), (int, float)) for key in ("x", "y", "theta")):
            raise CommandRefused("vda5050.instant_action: initPosition needs numbers x, y and theta (and mapId, lastNodeId)")
        if kind == "initPosition":
            parameters = {"mapId": master.roadmap.map_id, "lastNodeId": "", **parameters}
        assert master.control is not None
        action_id = f"{link.id}.{kind}.{uuid.uuid4().hex[:8]}"
        master.control.instant(link, action(kind, action_id, "HARD" if kind in ("cancelOrder", "initPosition") else "NONE", parameters))
        await master.flush()
        return {"robot": link.id, "action": kind, "action_id": action_id}

    view = Permission.VIEW
    return [
        commands.register("vda5050.vehicles", vehicles, permission=view, description="list the VDA 5050 vehicles"),
        commands.register("vda5050.roadmap", roadmap, permission=view, description="read the roadmap"),
        commands.register("vda5050.orders", orders, permission=view, description="list the vehicles' orders"),
        commands.register("vda5050.factsheets", factsheets, permission=view, description="list the vehicles' factsheets"),
        commands.register("vda5050.instant_action", instant_action, permission=Permission.ENGINEER,
                          description="send an instant action to a VDA 5050 vehicle",
                          arguments={"robot": "robot id", "action": "|".join(INSTANT_ACTIONS), "parameters": "action parameters"}),
    ]
