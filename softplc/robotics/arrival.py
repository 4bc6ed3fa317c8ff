"""When a robot counts as at its goal: one rule for the robot's driver and for the programs that send it.

A robot has arrived when it is within `GOAL_TOLERANCE` of its goal and has cleared `status`.
The driver (softplc.robotics.driver) clears `status` by exactly this distance, and the motion
sequencer (programs/motion_sequencer.py) accepts a robot at a station by exactly this rule, so
a robot the driver considers there is never left waiting for a sequencer that does not.
(The thesis used 0.5 m on the robot's side and 0.3 m in `robMotion`; two robots sent to one
station then both stopped between 0.3 and 0.5 m from it and stood still.)

Status cleared *farther* than the tolerance means the trip ended without arriving: the robot
gave up (navstate `failed`).

This module imports nothing else of softplc, so scan programs can use it freely.
"""

from __future__ import annotations

import math

GOAL_TOLERANCE = 0.5  # m (thesis Eq. 4.1)


def within_goal(x: float, y: float, goal_x: float, goal_y: float) -> bool:
    """True when (x, y) is within GOAL_TOLERANCE of the goal."""
    return math.hypot(goal_x - x, goal_y - y) <= GOAL_TOLERANCE


def has_arrived(x: float, y: float, goal_x: float, goal_y: float, busy: bool) -> bool:
    """True when the robot is at its goal: within GOAL_TOLERANCE and `status` cleared."""
    return not busy and within_goal(x, y, goal_x, goal_y)


def has_given_up(x: float, y: float, goal_x: float, goal_y: float, busy: bool) -> bool:
    """True when the robot cleared `status` away from its goal: the trip failed."""
    return not busy and not within_goal(x, y, goal_x, goal_y)
