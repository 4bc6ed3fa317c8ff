"""VDA 5050 (2.0, 2.1): the messages between a master control and its vehicles, shared by both sides.

`topics` names the MQTT topics, `schemas` holds the JSON Schemas written from the spec's tables,
`validation` checks a message against them (and the order rules a schema cannot say), `messages`
builds what a master sends (orders, instant actions) and reads what a vehicle sends (state,
connection, factsheet). softplc/adapters/vda5050 (the master control) and the VDA 5050 robot
agent (softplc/clients/robot_agent/vda5050) both use them.
"""
