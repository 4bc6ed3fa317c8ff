"""VDA 5050 master control: standard AGVs/AMRs (and our own robot agents) as robots of the fleet, over MQTT.

The `vda5050:` section (section.py, settings.py) names the roadmap and the protocol; the adapter
(adapter.py) connects to the `mqtt:` broker, turns each vehicle's state into the robot's tags
(vehicle.py), turns goals written to rNN_xgoal/ygoal into orders on the roadmap (orders.py),
releases the base so no two vehicles hold a node or lane at once (traffic.py), and offers its
view to the HMI and the `softplc vda5050` CLI through registered queries and commands
(commands.py). docs/vda5050.md.
"""
