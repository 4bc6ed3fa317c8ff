"""Traffic by reservation: no node or lane held twice, deadlocks broken by a re-route, idle vehicles sent aside."""

from __future__ import annotations

from pathlib import Path

import pytest
from vda5050_support import ROADMAP, LibVehicles, adapter, start_plant, vehicle_yaml, wait_for, write_plant

from softplc.adapters.vda5050.traffic import Reservations, lane_resource, node_resource
from softplc.protocols.vda5050.messages import VehicleState
from softplc.robotics.roadmap import load_roadmap

P1, P3 = (7.925, 5.925), (7.925, 2.925)


def test_a_base_grows_only_onto_free_nodes_and_lanes_and_is_given_back_behind() -> None:
    traffic = Reservations(load_roadmap(ROADMAP))
    assert traffic.stand("a", "p1") and traffic.stand("b", "p3")
    assert traffic.extend("a", ["p1", "p2", "p3", "l3"], 0, 0, 3) == 1  # p3 is b's: a's base ends at p2
    assert traffic.waits["a"].holder == "b" and "p3" in traffic.waits["a"].text
    assert traffic.extend("b", ["p3", "p2", "p1", "u3"], 0, 0, 3) == 0  # the lane p3-p2 leads to a's node p2
    assert traffic.deadlocks() == [["a", "b"]]
    traffic.release_all("b", keep_node="l3")  # b went elsewhere
    assert traffic.extend("a", ["p1", "p2", "p3", "l3"], 1, 1, 3) == 2  # p3 free now; l3 is b's
    traffic.release_behind("a", ["p1", "p2", "p3", "l3"], 2, 2)
    assert traffic.holder == {node_resource("p3"): "a", node_resource("l3"): "b"}
    # A passing place: out to l3 and back over p3; passing p3 the first time gives back nothing the base needs again.
    traffic.release_all("b")
    loop = ["p2", "p3", "l3", "p3", "p2"]
    assert traffic.extend("a", loop, 0, 0, 4) == 4
    traffic.release_behind("a", loop, 2, 4)  # at l3: p2, p3 and their lanes are ahead again
    assert traffic.nodes_of("a") == {"p2", "p3", "l3"} and lane_resource("p3", "l3") in traffic.held["a"]
    assert lane_resource("p2", "p3") == lane_resource("p3", "p2")  # a lane is one resource for both directions
    assert traffic.conflicts == 0


@pytest.fixture
def vda_5050_lib() -> None:
    LibVehicles.require()


def occupied(state: VehicleState) -> set[str]:
    """Where a vehicle physically is: the node it last passed, and while driving the edge it is on and that edge's end."""
    found = {node_resource(state.last_node_id)}
    if state.driving and state.edge_states:
        edge_id = state.edge_states[0][0]
        start, end = edge_id.split("-")
        found |= {lane_resource(start, end), node_resource(end)}
    return found


async def test_head_on_in_the_parking_column_is_a_deadlock_broken_by_a_detour(tmp_path: Path, mosquitto, vda_5050_lib) -> None:
    # r01 at p1 goes down the column to l3, r02 at p3 goes up it to u3: each holds what the other needs.
    robots = [vehicle_yaml(robot, serial, *point, manufacturer="acme", key="instantActions", speed=1.0)
              for robot, serial, point in (("r01", "v1", P1), ("r02", "v2", P3))]
    tagdb = write_plant(tmp_path, mosquitto.url, robots)
    runtime = await start_plant(tagdb)
    db = runtime.db
    master = adapter(runtime, "vda5050")
    overlaps: list[str] = []

    def watch(tags) -> None:  # after every batch of tag changes: are two vehicles on one node or lane?
        states = {name: link.state for name, link in master.links.items() if link.state is not None}
        if len(states) == 2:
            both = occupied(states["r01"]) & occupied(states["r02"])
            if both:
                overlaps.append(f"{sorted(both)} at {states['r01'].last_node_id}/{states['r02'].last_node_id}")
    undo = db.on_change(watch)
    vehicles = [{"manufacturer": "acme", "serialNumber": "v1", "x": P1[0], "y": P1[1], "lastNodeId": "p1"},
                {"manufacturer": "acme", "serialNumber": "v2", "x": P3[0], "y": P3[1], "lastNodeId": "p3"}]
    try:
        async with LibVehicles(mosquitto.port, vehicles, speed=1.0):
            await wait_for(lambda: db.value("r01_online") and db.value("r02_online"), 10, "both report")
            db.submit([("r01_xgoal", 7.925), ("r01_ygoal", 2.2), ("r01_status", True),
                       ("r02_xgoal", 7.925), ("r02_ygoal", 6.6), ("r02_status", True)], "test")
            await wait_for(lambda: db.value("r01_navstate") == "arrived" and db.value("r02_navstate") == "arrived", 60,
                           "both arrived")
            assert master.control.deadlocks_broken >= 1
            assert overlaps == [] and master.control.traffic.conflicts == 0
            assert master.links["r02"].state.last_node_id == "u3" and master.links["r01"].state.last_node_id == "l3"
    finally:
        undo()
        await runtime.stop()
