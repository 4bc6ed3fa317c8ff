"""Robotics: robot and task files, compatibility (case II), occupancy maps, A* planning, the robot
driver and controller, traffic rules and the remote-robot tag protocol.

A library: used by the fleet adapter (robots driven in the runtime), the robot agent (a robot on its
own computer) and the scenarios. It imports no adapter.
"""
